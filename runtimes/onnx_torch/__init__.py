"""The CUDA backend's ONNX interpreter: an ONNX graph run as a ``torch.nn.Module``.

Only ``backends/cuda.py`` imports this package, and only the backend table imports that, when
``cuda`` (or ``auto`` on a machine with a GPU) is asked for; nothing on the CPU path needs torch.

    interpreter.py  the graph -> module builder, constant folding, shape propagation
    tensor_ops.py   element-wise, shape, indexing and reduction ops
    spatial_ops.py  convolution, pooling, padding and resizing
"""
