#!/usr/bin/env python3
"""What a user would otherwise run: one robot's GCN + collective-GRU step in PyTorch
eager and in onnxruntime-Python, on one thread, for comparison with the Rust figures
(`cargo bench -p spwi-agent --features ort --bench stages`, docs/BENCHMARKS.md).

onnxruntime runs the shipped ONNX files on their reference inputs. PyTorch runs the
same architecture (models/train/nets.py) at the same shapes; the weights are random,
which does not change the work done.

Usage: bench_python.py [models/default] [--runs 2000]
"""
import argparse
import json
import os
import time

import numpy as np
import onnxruntime as ort
import torch

from data import EMBEDDING, KEYPOINTS
from nets import GCN, TemporalGRU


def timed(fn, runs):
    for _ in range(min(200, runs)):
        fn()
    samples = []
    for _ in range(runs):
        t0 = time.perf_counter_ns()
        fn()
        samples.append((time.perf_counter_ns() - t0) / 1e3)
    samples.sort()
    return samples[len(samples) // 2], samples[int(0.99 * (len(samples) - 1))]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("set", nargs="?", default=os.path.join(os.path.dirname(__file__), "..", "default"))
    ap.add_argument("--runs", type=int, default=2000)
    a = ap.parse_args()
    torch.set_num_threads(1)
    with open(os.path.join(a.set, "manifest.json")) as f:
        manifest = json.load(f)
    with open(os.path.join(a.set, "reference.json")) as f:
        ref = json.load(f)

    def feeds(name):
        return {k: np.array(v["data"], np.float32).reshape(v["shape"]) for k, v in ref[name]["inputs"].items()}

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = 1
    opts.inter_op_num_threads = 1
    rows = []
    sessions = {}
    for name in ("gcn", "collective_gru"):
        sess = ort.InferenceSession(os.path.join(a.set, manifest["models"][name]["file"]), opts, providers=["CPUExecutionProvider"])
        sessions[name] = (sess, feeds(name))
        p50, p99 = timed(lambda s=sess, f=feeds(name): s.run(None, f), a.runs)
        rows.append(("onnxruntime-Python", name, p50, p99))

    gcn = GCN().eval()
    gru = TemporalGRU(2 * EMBEDDING + KEYPOINTS, manifest["horizon"]).eval()
    g_in = [torch.from_numpy(v) for v in feeds("gcn").values()]
    r_in = torch.from_numpy(next(iter(feeds("collective_gru").values())))
    with torch.inference_mode():
        for name, fn in (("gcn", lambda: gcn(*g_in)), ("collective_gru", lambda: gru(r_in))):
            p50, p99 = timed(fn, a.runs)
            rows.append(("PyTorch eager", name, p50, p99))

    def step_ort():
        for s, f in sessions.values():
            s.run(None, f)

    def step_torch():
        with torch.inference_mode():
            gcn(*g_in)
            gru(r_in)

    for label, fn in (("onnxruntime-Python", step_ort), ("PyTorch eager", step_torch)):
        p50, p99 = timed(fn, a.runs)
        rows.append((label, "gcn + collective_gru", p50, p99))
    print(f"model set {manifest['name']}, one thread, {a.runs} runs each (torch {torch.__version__}, onnxruntime {ort.__version__})")
    print(f"{'runtime':<20} {'model':<22} {'p50 µs':>8} {'p99 µs':>8}")
    for r in rows:
        print(f"{r[0]:<20} {r[1]:<22} {r[2]:>8.1f} {r[3]:>8.1f}")


if __name__ == "__main__":
    main()
