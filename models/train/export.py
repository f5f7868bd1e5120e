"""ONNX export with every check the issue asks for, and the files shipped beside a model.

Each model is exported at batch 1 with fixed shapes (opset 17, IR version 8 so that
onnxruntime 1.31 and tract read it), except the GCN's node count (node_dim.py), then:
- `onnx.checker` (full check);
- every GRU node must carry linear_before_reset=1 (PyTorch's GRU; some exporter versions
  wrote 0, which runs without complaint and silently predicts worse);
- onnxruntime's outputs on the reference inputs must match PyTorch's within 1e-4;
- the reference inputs (real samples, rounded to 4 decimals so JSON holds them exactly)
  and onnxruntime's outputs go to reference.json, which the Rust golden tests replay
  through tract and ort.
"""
import hashlib

import numpy as np
import onnx
import onnxruntime as ort
import torch

from node_dim import set_node_dim

OPSET = 17
IR_VERSION = 8
TOLERANCE = 1e-4


def export(model, inputs, input_names, output_names, path, named_nodes=False):
    """Exports `model` (eval mode) for `inputs` (batch 1); returns the reference entry.
    `named_nodes`: a GCN, whose node dimension is then named (node_dim.py)."""
    model.eval()
    inputs = tuple(torch.from_numpy(np.round(i.numpy(), 4).astype(np.float32)) for i in inputs)
    torch.onnx.export(
        model, inputs, path, input_names=input_names, output_names=output_names, opset_version=OPSET, dynamo=False
    )
    m = onnx.load(path)
    m.ir_version = IR_VERSION
    if named_nodes:
        set_node_dim(m)
    onnx.checker.check_model(m, full_check=True)
    for node in m.graph.node:
        if node.op_type == "GRU":
            lbr = {a.name: a.i for a in node.attribute}.get("linear_before_reset", 0)
            if lbr != 1:
                raise SystemExit(f"{path}: GRU node {node.name} has linear_before_reset={lbr}; PyTorch's GRU needs 1")
    onnx.save(m, path)
    with torch.no_grad():
        want = model(*inputs)
    want = want if isinstance(want, tuple) else (want,)
    sess = ort.InferenceSession(path, providers=["CPUExecutionProvider"])
    feeds = {n: i.numpy() for n, i in zip(input_names, inputs)}
    got = sess.run(None, feeds)
    for name, w, g in zip(output_names, want, got):
        worst = float(np.abs(w.numpy() - g).max())
        if worst > TOLERANCE:
            raise SystemExit(f"{path}: onnxruntime's {name} differs from PyTorch's by {worst} > {TOLERANCE}")
    return {
        "inputs": {n: {"shape": list(v.shape), "data": [float(x) for x in v.ravel()]} for n, v in feeds.items()},
        "outputs": {n: {"shape": list(v.shape), "data": [float(x) for x in v.ravel()]} for n, v in zip(output_names, got)},
    }


def io_spec(path):
    """The manifest entry of the ONNX file at `path` (besides its name): its SHA-256,
    which the daemon checks at start, and its inputs and outputs."""
    m = onnx.load(path)
    with open(path, "rb") as f:
        digest = hashlib.sha256(f.read()).hexdigest()

    def shape(vi):
        return [d.dim_param or d.dim_value for d in vi.type.tensor_type.shape.dim]

    return {
        "sha256": digest,
        "inputs": [{"name": i.name, "shape": shape(i)} for i in m.graph.input],
        "outputs": [{"name": o.name, "shape": shape(o)} for o in m.graph.output],
    }
