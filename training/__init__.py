"""Training of the camera segmentation networks (PyTorch). Never imported by the build or the
nodes: the nodes run the exported ONNX model through OpenCV dnn (perception/segmenter.h)."""
