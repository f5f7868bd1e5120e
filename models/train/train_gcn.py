#!/usr/bin/env python3
"""Stage 1: trains the GCN on the spatial part of one or more exports and exports it.

Usage: train_gcn.py --data DIR [DIR ...] --out DIR [--epochs 12] [--seed 1]
Writes OUT/gcn.onnx, OUT/gcn_reference.json and OUT/gcn.json (the graphs it reads —
max_nodes, edge_weight, node_features, as the exports describe them — settings, test
accuracy per scenario, time). The graph's node features are the exports' (`spwi-sim
dataset --node-features`): appearance (the paper's) or appearance and floor relations.
The temporal datasets are then exported by running this gcn.onnx
through the agent's own Rust code (`spwi-sim dataset --gcn OUT/gcn.onnx`).
"""
import argparse
import json
import os
import time

import numpy as np
import torch
from torch import nn

from data import SPLITS, Export
from export import export
from nets import GCN
from set_gcn import graph_of


def load(paths):
    parts = {"x": [], "adj": [], "label": [], "split": [], "scenario": []}
    graphs = set()
    for p in paths:
        ex = Export(p)
        graphs.add(tuple(graph_of({}, ex.desc).items()))  # how its graphs are built
        for k in ("x", "adj", "label", "split"):
            parts[k].append(np.asarray(ex.spatial(k)))
        parts["scenario"].append(np.full(len(parts["label"][-1]), ex.scenario, np.int64))
    if len(graphs) != 1:
        raise SystemExit(f"the exports build their graphs differently: {sorted(graphs)}")
    return {k: np.concatenate(v) for k, v in parts.items()}, dict(graphs.pop())


def accuracy(model, x, adj, y, batch=1024):
    model.eval()
    hits = 0
    with torch.no_grad():
        for i in range(0, len(y), batch):
            _, logits = model(x[i : i + batch], adj[i : i + batch])
            hits += int((logits.argmax(1) == y[i : i + batch]).sum())
    return hits / max(len(y), 1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--data", nargs="+", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--threads", type=int, default=2)
    a = ap.parse_args()
    torch.manual_seed(a.seed)
    torch.set_num_threads(a.threads)
    started = time.time()
    d, graph = load(a.data)
    x, adj = torch.from_numpy(d["x"]), torch.from_numpy(d["adj"])
    y = torch.from_numpy(d["label"].astype(np.int64))
    sel = {s: torch.from_numpy(np.flatnonzero(d["split"] == v)) for s, v in SPLITS.items()}
    print(f"gcn: {len(y)} graphs ({', '.join(f'{s} {len(i)}' for s, i in sel.items())})", flush=True)

    model = GCN(features=x.shape[-1])
    opt = torch.optim.AdamW(model.parameters(), lr=1e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, a.epochs)
    loss_fn = nn.CrossEntropyLoss()
    train = sel["train"]
    best, best_state = -1.0, None
    for epoch in range(a.epochs):
        model.train()
        perm = train[torch.randperm(len(train))]
        for i in range(0, len(perm), 128):
            b = perm[i : i + 128]
            _, logits = model(x[b], adj[b])
            loss = loss_fn(logits, y[b])
            opt.zero_grad()
            loss.backward()
            opt.step()
        sched.step()
        v = sel["validation"]
        acc = accuracy(model, x[v], adj[v], y[v])
        if acc > best:
            best, best_state = acc, {k: t.clone() for k, t in model.state_dict().items()}
        print(f"  epoch {epoch + 1}/{a.epochs}: loss {loss.item():.3f}, validation accuracy {acc:.3f}", flush=True)
    model.load_state_dict(best_state)

    test = sel["test"]
    per_scenario = {}
    for s in sorted(set(d["scenario"].tolist())):
        i = test[torch.from_numpy(d["scenario"][test.numpy()] == s)]
        per_scenario[str(s)] = round(accuracy(model, x[i], adj[i], y[i]), 4)
    os.makedirs(a.out, exist_ok=True)
    path = os.path.join(a.out, "gcn.onnx")
    ref_index = int(test[0])
    reference = export(
        model, (x[ref_index : ref_index + 1], adj[ref_index : ref_index + 1]), ["x", "adj"], ["embedding", "logits"], path,
        named_nodes=True,
    )
    with open(os.path.join(a.out, "gcn_reference.json"), "w") as f:
        json.dump(reference, f, separators=(",", ":"))
    report = {
        **graph,
        "graphs": {s: len(i) for s, i in sel.items()},
        "epochs": a.epochs,
        "seed": a.seed,
        "validation_accuracy": round(best, 4),
        "test_accuracy_by_scenario": per_scenario,
        "seconds": round(time.time() - started, 1),
    }
    with open(os.path.join(a.out, "gcn.json"), "w") as f:
        json.dump(report, f, indent=2)
    print(f"gcn: test accuracy by scenario {per_scenario}, {report['seconds']} s", flush=True)


if __name__ == "__main__":
    main()
