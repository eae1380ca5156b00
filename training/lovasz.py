"""The Lovasz-softmax loss (Berman, Rannen Triki and Blaschko, CVPR 2018): a convex surrogate of
1 - IoU per class, optimised directly where cross-entropy optimises pixel accuracy.

For one class c with ground-truth pixels F and a set M of mispredicted pixels, the Jaccard loss
is |M| / |F u M|. The Lovasz extension of this set function at the vector of per-pixel errors
m_i = |[i in F] - p_i(c)| sorts the errors in decreasing order and sums each error times the
increase of the set function when its pixel joins the mispredicted set:

    loss_c = sum_k m_(k) (D_k - D_(k-1)),   D_k = k / (|F| + number of non-F pixels among the
    first k),  D_0 = 0.

With one-hot probabilities the errors are 0 or 1 and the sum is exactly 1 - IoU_c, which is what
the tests check. The loss averages over the classes present in the labels of the batch.
"""

from __future__ import annotations


def lovasz_softmax(probabilities, target, ignore_index, torch):
    """probabilities: N x C x H x W softmax output; target: N x H x W class indices (ignore_index
    where unlabelled). Returns the mean over the classes present in target of the Lovasz
    extension of each class's Jaccard loss, over all labelled pixels of the batch (a scalar
    tensor; zero when nothing is labelled)."""
    num_classes = probabilities.shape[1]
    flat = probabilities.permute(0, 2, 3, 1).reshape(-1, num_classes)
    labels = target.reshape(-1)
    keep = labels != ignore_index
    flat, labels = flat[keep], labels[keep]
    if labels.numel() == 0:
        return probabilities.sum() * 0.0
    losses = []
    for c in torch.unique(labels).tolist():
        if c >= num_classes:
            continue
        foreground = (labels == c).to(flat.dtype)
        errors = (foreground - flat[:, c]).abs()
        errors_sorted, order = torch.sort(errors, descending=True)
        fg_sorted = foreground[order]
        k = torch.arange(1, fg_sorted.numel() + 1, dtype=flat.dtype, device=flat.device)
        jaccard = k / (foreground.sum() + torch.cumsum(1.0 - fg_sorted, 0))
        increments = torch.cat([jaccard[:1], jaccard[1:] - jaccard[:-1]])
        losses.append(torch.dot(errors_sorted, increments))
    if not losses:
        return probabilities.sum() * 0.0
    return torch.stack(losses).mean()
