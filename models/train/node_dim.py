#!/usr/bin/env python3
"""Names the GCN's node dimension ("nodes") instead of fixing it at max_nodes.

A GCN whose inputs are x [1, nodes, 1024] and adj [1, nodes, nodes] is fed only the
graph's real nodes (the worker and the objects seen, usually 2 to 5) instead of all
max_nodes padded ones: the two layers' products shrink with it, and the worker node's
output is the same (padding rows have no edge to it). Nothing else in the graph may
depend on the node count; the daemon refuses a node dimension named in some inputs and
fixed in others.

export.py applies it to every GCN it exports. Run on existing files (onnx only):
    python3 models/train/node_dim.py models/default/gcn.onnx ...
"""
import sys

import onnx

NAME = "nodes"


def name_node_dim(model):
    """Names dimension 1 of x and dimensions 1 and 2 of adj, in place."""
    axes = {"x": (1,), "adj": (1, 2)}
    for i in model.graph.input:
        for axis in axes.get(i.name, ()):
            dim = i.type.tensor_type.shape.dim[axis]
            dim.Clear()
            dim.dim_param = NAME
    missing = set(axes) - {i.name for i in model.graph.input}
    if missing:
        raise SystemExit(f"not a GCN: no input named {sorted(missing)}")
    del model.graph.value_info[:]  # shapes inferred for the fixed size no longer hold
    onnx.checker.check_model(model, full_check=True)


def main():
    for path in sys.argv[1:]:
        m = onnx.load(path)
        name_node_dim(m)
        onnx.save(m, path)
        print(f"{path}: node dimension named {NAME!r}")


if __name__ == "__main__":
    main()
