"""Running mean of a network's weights over the steps of a training run (stochastic weight
averaging, Izmailov et al. 2018; dense averaging along the run as in SWAD, Cha et al. 2021).

Why it is here: the fine-tuning sees about a hundred labelled images, and two runs of the same
command label an unseen sequence differently. These papers find the mean of the weights visited
late in a run generalises better under a change of domain than any one point of it. On KITTI's
05 / 08 it did not (docs/segmentation_adaptation.md), so it is an option (--average-weights),
off by default.

Floating-point tensors (weights, biases and, when the run updates them, the batch-normalisation
statistics) are averaged; integer buffers (batch counters) are the latest. The statistics are
averaged rather than measured again for the mean weights (as the paper does): measured again over
the training images, they validated worse (docs/segmentation_adaptation.md).
"""


class WeightAverage:
    """Equal-weight mean of the state dicts given to add(), kept in float32 on the CPU."""

    def __init__(self):
        self.count = 0
        self._mean = None
        self._dtypes = None

    def add(self, state_dict):
        self.count += 1
        if self._mean is None:
            self._dtypes = {k: v.dtype for k, v in state_dict.items()}
            self._mean = {k: v.detach().to("cpu", copy=True).float() if v.is_floating_point()
                          else v.detach().to("cpu", copy=True) for k, v in state_dict.items()}
            return
        if state_dict.keys() != self._mean.keys():
            missing = sorted(set(self._mean) ^ set(state_dict))
            raise ValueError("the state to average has other tensors than the first: "
                             f"{missing[:5]}")
        for key, value in state_dict.items():
            value = value.detach().to("cpu")
            if value.is_floating_point():
                self._mean[key] += (value.float() - self._mean[key]) / self.count
            else:
                self._mean[key] = value.clone()

    def state_dict(self):
        """The mean so far, each tensor in the dtype it was given in."""
        if self._mean is None:
            raise ValueError("no weights were averaged")
        return {k: v.to(self._dtypes[k]) for k, v in self._mean.items()}

