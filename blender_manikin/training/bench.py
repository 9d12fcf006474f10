"""Measure training speed of candidate model configurations on this machine.

    python -m blender_manikin.training.bench [--bvh SRC] [--threads 2] [--steps 20]
        [--config D_MODEL:LAYERS:HEADS:BATCH ...]

For each configuration prints the parameter count, the median time of one
optimizer step on ready batches (forward, MANIKIN loss, backward, AdamW),
the time to make one batch (numpy) and the end-to-end rate with batches made
ahead in a worker process, as training does.  Without ``--bvh`` synthetic
clips are used (the speed does not depend on the data).  The machine load
average is printed because other processes on a shared machine change the
numbers.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np

DEFAULT_CONFIGS = ("128:3:4:32", "128:3:4:64", "160:3:4:48", "192:3:4:48", "192:3:6:64")


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m blender_manikin.training.bench")
    ap.add_argument("--bvh", default=None)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--steps", type=int, default=20)
    ap.add_argument("--window", type=int, default=40)
    ap.add_argument("--kind", default="manikin")
    ap.add_argument("--config", nargs="*", default=list(DEFAULT_CONFIGS))
    ap.add_argument("--data-workers", type=int, default=1, help="as in train.py (0: batches made in-process)")
    a = ap.parse_args(argv)

    from . import dataset as ds
    if a.bvh:
        files = ds.build_cache(a.bvh)
        files = ds.split_files(files)[0]
    else:
        rng = np.random.default_rng(0)
        tmp = tempfile.mkdtemp(prefix="manikin_bench_")
        files = []
        for i in range(8):
            rec = ds.motion_to_record(ds.synthetic_motion(rng, T=300, take_id=f"b{i}"), f"b{i}", "synthetic")
            files.append(os.path.join(tmp, f"b{i}.npz"))
            np.savez(files[-1], **rec)
    clips = ds.ClipSet.load(files)
    samplers = {}
    import torch
    from . import losses
    from .model import ModelConfig, PoseNet, count_parameters
    torch.set_num_threads(a.threads)
    print(f"threads {a.threads}, data workers {a.data_workers}, window {a.window}, kind {a.kind}, "
          f"load average {os.getloadavg()}")
    print(f"{'d_model':>7} {'layers':>6} {'heads':>5} {'batch':>5} {'params':>9} {'step ms':>8} "
          f"{'batch ms':>8} {'steps/s':>8} {'e2e steps/s':>11}")
    rows = []
    for spec in a.config:
        d, L, h, B = (int(v) for v in spec.split(":"))
        if B not in samplers:
            samplers[B] = ds.WindowSampler(clips, window=a.window, kind=a.kind, seed=0)
        s = samplers[B]
        t = time.perf_counter()
        batches = [s.batch_for_step(i, B) for i in range(4)]
        t_batch = (time.perf_counter() - t) / 4
        torch.manual_seed(0)
        model = PoseNet(ModelConfig(kind=a.kind, window=a.window, d_model=d, layers=L, heads=h))
        opt = torch.optim.AdamW(model.parameters(), 1e-3)
        tb = [losses.to_torch(b) for b in batches]

        def step(b):
            y = model(b["x"])
            tot, _, _ = losses.compute_loss(y, b, a.kind)
            opt.zero_grad()
            tot.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
        for i in range(3):
            step(tb[i % 4])
        times = []
        for i in range(a.steps):
            t = time.perf_counter()
            step(tb[i % 4])
            times.append(time.perf_counter() - t)
        t_step = float(np.median(times))
        pf = ds.Prefetcher(s, B, 0, 0, workers=a.data_workers)
        t = time.perf_counter()
        n = max(a.steps // 2, 5)
        for i in range(n):
            step(losses.to_torch(pf.get(i)))
        e2e = n / (time.perf_counter() - t)
        pf.close()
        rows.append(dict(d_model=d, layers=L, heads=h, batch=B, params=count_parameters(model),
                         step_ms=t_step * 1e3, batch_ms=t_batch * 1e3, e2e=e2e))
        print(f"{d:7d} {L:6d} {h:5d} {B:5d} {count_parameters(model):9,d} {t_step * 1e3:8.0f} "
              f"{t_batch * 1e3:8.0f} {1 / t_step:8.2f} {e2e:11.2f}   (windows/s {e2e * B:.0f})", flush=True)
    print(f"load average after: {os.getloadavg()}")
    return rows


if __name__ == "__main__":
    main()
