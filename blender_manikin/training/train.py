"""Train the pose network from a folder / archive of BVH files.

    python -m blender_manikin.training.train --bvh DIR_OR_ARCHIVE --out DIR
        [--kind manikin|fk] [--minutes 60] [--steps N] [--batch 48] [--window 40]
        [--seed 0] [--resume] [--threads 2] [--d-model 160] [--six-trackers] ...

* Data: :func:`dataset.build_cache` (parsed once, cached outside the repo),
  whole takes held out for validation (``split.json`` in the cache).
* Plan: ``--steps`` and/or ``--minutes`` (wall clock of this run plus any
  resumed runs; 60 when neither is given).  The learning rate warms up
  linearly, then follows a cosine to 5 % over the plan; with a time budget
  the plan's progress is the elapsed fraction of it.
* AdamW, gradient clipping at 1, fixed seed (torch and numpy); a one-line
  progress bar on stderr (step, loss, steps/s, ETA).
* ``DIR/checkpoint.pt`` (model, optimizer, step, elapsed time, config, rng
  states, data description, validation history) every ``--ckpt-minutes``
  and at the end, written atomically.  ``--resume`` continues from it
  exactly (same batches, same dropout) and may extend the plan.
* ``--ema DECAY`` keeps a moving average of the weights
  (:mod:`.weight_average`); validation, ``best.pt`` and export then use it.
* Validation loss and metrics (MPJPE, hand/upper/lower errors in cm, root
  orientation error, contact accuracy) on fixed windows of the held-out
  takes, printed on stdout at every checkpoint and appended to
  ``DIR/metrics.jsonl``.

Then export: ``python -m blender_manikin.training.export --checkpoint DIR/checkpoint.pt
--out blender_manikin/models/manikin_s.onnx``.
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import sys
import time


from ..core import features
from .weight_average import WeightAverage
from ..core.devices import DEVICES

SIX_TRACKERS = DEVICES


def build_parser():
    p = argparse.ArgumentParser(prog="python -m blender_manikin.training.train", description=__doc__.split("\n\n")[0])
    p.add_argument("--bvh", action="append", default=None, metavar="SOURCE",
                   help="a training source: folder, file or tar archive of BVH or ASF/AMC takes (repeatable)")
    p.add_argument("--sources", default=None, metavar="FILE.json",
                   help="training sources, each with its joint map, units, axes, fps and licence "
                        "(a JSON list; see training/dataset.py MotionSource); instead of --bvh")
    p.add_argument("--out", required=True, help="run folder (checkpoint.pt, metrics.jsonl)")
    p.add_argument("--kind", choices=sorted(features.OUTPUT_BLOCKS), default="manikin")
    p.add_argument("--minutes", type=float, default=None, help="time budget (default 60 without --steps)")
    p.add_argument("--steps", type=int, default=None, help="number of optimizer steps")
    p.add_argument("--batch", type=int, default=48)
    p.add_argument("--window", type=int, default=None,
                   help="frames per network window (default 40; with --init, widens or narrows the "
                        "model's window, its positional embedding lined up at the centre frame)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--resume", action="store_true",
                   help="continue OUT/checkpoint.pt with its model, data, seed, batch and optimizer settings, "
                        "its --select-on source and validation windows (--steps / --minutes may extend the plan)")
    p.add_argument("--init", default=None, metavar="PATH",
                   help="start a new run from these weights (a checkpoint .pt or an exported .onnx; its "
                        "architecture and devices replace --arch, --d-model, --devices...): fine-tuning")
    p.add_argument("--overwrite", action="store_true", help="start afresh even if OUT/checkpoint.pt exists")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--d-model", type=int, default=160)
    p.add_argument("--layers", type=int, default=3)
    p.add_argument("--heads", type=int, default=4)
    p.add_argument("--ff-mult", type=int, default=4)
    p.add_argument("--head-hidden", type=int, default=256)
    p.add_argument("--dropout", type=float, default=0.05,
                   help="residual and attention dropout while training (also with --init; a resumed run keeps its own)")
    p.add_argument("--causal", action="store_true",
                   help="live variant: attend to past frames only (with --init, only from a causal model)")
    p.add_argument("--arch", choices=("posenet", "dap"), default=None,
                   help="backbone: posenet (default: shared Transformer, global + local heads) or dap (Dual "
                        "Attention Poser: global and local paths, cross-attention mixer, gated-MLP decoders); "
                        "with --init, the weights' own (another is refused)")
    p.add_argument("--six-trackers", action="store_true", help="inputs: head, hands, pelvis and feet")
    p.add_argument("--devices", default=None, metavar="D1,D2,...",
                   help="input devices, comma-separated, in any order (head and hands required), e.g. "
                        "head,left_hand,right_hand,pelvis; default head and hands")
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--lam", action="append", default=None, metavar="TERM=WEIGHT",
                   help="override a loss weight of losses.LAMBDA, e.g. --lam mid=1.0 (repeatable; "
                        "a resumed run keeps its weights unless given again)")
    p.add_argument("--aug", action="append", default=None, metavar="FIELD=VALUE",
                   help="override an augmentation setting of dataset.Augment, e.g. --aug arm_mix=0 "
                        "(repeatable; a resumed run keeps its settings unless given again)")
    p.add_argument("--balance", type=float, default=None, metavar="B",
                   help="draw windows less in proportion to each motion class's frames (0 to 1; "
                        "dataset.WindowSampler.clip_probabilities): a class's share goes as its frames to "
                        "the power 1 - B, so rare classes (kicks, dance) are seen more; 0 (default): every "
                        "frame alike (a resumed run keeps its setting unless given again)")
    p.add_argument("--weight-decay", type=float, default=0.01)
    p.add_argument("--ema", type=float, default=0.0, metavar="DECAY",
                   help="keep an exponential moving average of the weights with this decay (e.g. 0.999, "
                        "about the last 1,000 steps); validation, best.pt and export then use the "
                        "averaged weights (training/weight_average.py); 0 (default): off")
    p.add_argument("--warmup", type=int, default=300, help="warm-up steps (at most 5 %% of a step plan)")
    p.add_argument("--ckpt-minutes", type=float, default=5.0, help="checkpoint + validation interval")
    p.add_argument("--ckpt-steps", type=int, default=None, help="also checkpoint every N steps")
    p.add_argument("--val-windows", type=int, default=None, help="validation windows (default 384)")
    p.add_argument("--select-on", default=None, metavar="SOURCE",
                   help="a motion source never trained on (e.g. ../shared/data/validation/hdm05-subset.tar.xz): "
                        "evaluated at every checkpoint, and OUT/best.pt keeps the checkpoint with the lowest "
                        "MPJPE on it (models are chosen on other people's motion, not on held-out takes)")
    p.add_argument("--cache-dir", default=None, help="dataset cache root (default ~/.cache/blender_manikin/dataset)")
    p.add_argument("--workers", type=int, default=2, help="processes for building the cache")
    p.add_argument("--data-workers", type=int, default=0,
                   help="processes making training batches ahead; 0 (default) makes them in the training "
                        "process, faster on 2 cores where a worker competes with torch's threads")
    p.add_argument("--stop-at", type=int, default=None,
                   help="stop this invocation at this step (checkpointed) without changing the plan; "
                        "--resume continues it")
    p.add_argument("--quiet", action="store_true")
    return p


def parse_devices(text, six_trackers=False):
    """The model's input devices from ``--devices`` (canonical ``DEVICES`` order)."""
    if text is None:
        return SIX_TRACKERS if six_trackers else features.INPUT_DEVICES
    names = [t.strip() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in DEVICES]
    if unknown:
        raise SystemExit(f"--devices: unknown device(s) {unknown}; known: {', '.join(DEVICES)}")
    missing = [d for d in features.INPUT_DEVICES if d not in names]
    if missing:
        raise SystemExit(f"--devices: {', '.join(missing)} required")
    return tuple(d for d in DEVICES if d in names)


class Progress:
    """One updating status line on stderr (a plain line every 30 s when not a terminal)."""

    def __init__(self, enabled=True):
        self.enabled = enabled
        self.tty = sys.stderr.isatty()
        self.last = 0.0
        self.width = 0

    def update(self, text, force=False):
        if not self.enabled:
            return
        now = time.time()
        if not force and now - self.last < (0.5 if self.tty else 30.0):
            return
        self.last = now
        if self.tty:
            sys.stderr.write("\r" + text.ljust(self.width))
            self.width = len(text)
        else:
            sys.stderr.write(text + "\n")
        sys.stderr.flush()

    def newline(self):
        if self.enabled and self.tty and self.width:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.width = 0


def _fmt_time(s):
    s = max(int(s), 0)
    return f"{s // 3600}:{s // 60 % 60:02d}:{s % 60:02d}" if s >= 3600 else f"{s // 60}:{s % 60:02d}"


def lr_factor(progress, step, warmup):
    if warmup > 0 and step < warmup:
        return (step + 1) / warmup
    return 0.05 + 0.95 * 0.5 * (1.0 + math.cos(math.pi * min(max(progress, 0.0), 1.0)))


def _save(path, obj):
    import torch
    tmp = path + ".tmp"
    torch.save(obj, tmp)
    os.replace(tmp, path)


def parse_lam(items):
    """``["mid=1.0", ...]`` → ``{"mid": 1.0}``, checked against :data:`losses.LAMBDA`."""
    from . import losses
    out = {}
    for it in items or []:
        k, sep, v = it.partition("=")
        if not sep or k.strip() not in losses.LAMBDA:
            raise SystemExit(f"--lam {it!r}: expected TERM=WEIGHT with TERM one of {sorted(losses.LAMBDA)}")
        try:
            out[k.strip()] = float(v)
        except ValueError:
            raise SystemExit(f"--lam {it!r}: {v!r} is not a number") from None
    return out


def parse_aug(items):
    """``["arm_mix=0", "stature=1.5,2.0", ...]`` → a :class:`dataset.Augment`, checked."""
    from . import dataset
    aug = dataset.Augment()
    for it in items or []:
        k, sep, v = it.partition("=")
        k = k.strip()
        if not sep or k not in dataset.Augment.__dataclass_fields__:
            raise SystemExit(f"--aug {it!r}: expected FIELD=VALUE with FIELD one of "
                             f"{sorted(dataset.Augment.__dataclass_fields__)}")
        try:
            vals = [float(x) for x in v.split(",")] if v.strip().lower() != "none" else None
        except ValueError:
            raise SystemExit(f"--aug {it!r}: {v!r} is not a number or a comma-separated pair") from None
        current = getattr(aug, k)
        if vals is not None and isinstance(current, tuple) != (len(vals) == 2) and current is not None:
            raise SystemExit(f"--aug {it!r}: {k} takes " + ("two numbers (LOW,HIGH)" if isinstance(current, tuple)
                                                              else "one number"))
        setattr(aug, k, None if vals is None else (tuple(vals) if len(vals) == 2 else vals[0]))
    try:
        aug.check()
    except ValueError as exc:
        raise SystemExit(f"--aug: {exc}") from None
    return aug


def evaluate(model, val_batches, kind, devices, lam=None):
    import torch
    from . import losses
    model.eval()
    parts, loss_sum, n = [], 0.0, 0
    with torch.no_grad():
        for b in val_batches:
            bt = losses.to_torch(b)
            y = model(bt["x"])
            tot, _, a = losses.compute_loss(y, bt, kind, devices, lam=lam)
            B = y.shape[0]
            loss_sum += float(tot) * B
            n += B
            parts.append(losses.metrics(y, bt, kind, devices, assembled=a))
    model.train()
    m = losses.reduce_metrics(parts)
    m["loss"] = loss_sum / max(n, 1)
    return m


def main(argv=None):
    args = build_parser().parse_args(argv)
    import torch
    from . import dataset, losses
    from .backbones import build_model
    from .model import ModelConfig, count_parameters
    from ..core.version import __version__

    torch.set_num_threads(max(1, args.threads))
    try:
        torch.set_num_interop_threads(1)
    except RuntimeError:
        pass
    os.makedirs(args.out, exist_ok=True)
    ckpt_path = os.path.join(args.out, "checkpoint.pt")
    say = (lambda *a: None) if args.quiet else (lambda *a: print(*a, flush=True))

    ckpt = None
    if os.path.exists(ckpt_path):
        if args.resume:
            ckpt = torch.load(ckpt_path, map_location="cpu", weights_only=False)
        elif not args.overwrite:
            raise SystemExit(f"{ckpt_path} exists: pass --resume to continue it or --overwrite to start afresh")
    elif args.resume:
        say(f"no checkpoint at {ckpt_path}; starting a new run")

    if ckpt is not None:
        # a resumed run keeps its identity: data, seed, batch and optimizer settings
        prev = ckpt["args"]
        # and how it is validated and chosen: the --select-on source, its windows, the checkpoints
        for k in ("bvh", "sources", "cache_dir", "select_on", "val_windows", "ckpt_steps"):
            if getattr(args, k) is None:
                setattr(args, k, prev.get(k))
        if isinstance(args.bvh, str):            # runs from before several sources
            args.bvh = [args.bvh]
        for k in ("seed", "batch", "lr", "weight_decay", "warmup", "ema"):
            if k in prev:
                setattr(args, k, prev[k])
        if args.lam is None:
            args.lam = prev.get("lam")
        if args.balance is None:
            args.balance = prev.get("balance")
        if args.aug is None:
            # runs from before --aug used the defaults of their time: the arm mix and tracker
            # dropouts came later
            args.aug = prev.get("aug", ["arm_mix=0", "dropout=0"])
        if args.steps is None and args.minutes is None:
            args.steps, args.minutes = prev.get("steps"), prev.get("minutes")
        cfg = ModelConfig.from_dict(ckpt["config"])
        args.kind, args.window = cfg.kind, cfg.window
    if args.steps is None and args.minutes is None:
        args.minutes = 60.0
    if args.val_windows is None:
        args.val_windows = 384
    if not args.bvh and not args.sources:
        raise SystemExit("--bvh SOURCE or --sources FILE.json is required")
    lam = parse_lam(args.lam)
    aug = parse_aug(args.aug)
    if args.balance is None:
        args.balance = 0.0
    if not 0.0 <= args.balance <= 1.0:
        raise SystemExit(f"--balance {args.balance}: expected a number from 0 to 1")
    init_state = None
    if ckpt is None and args.init:
        from .init_weights import load_initial_weights
        try:
            cfg, init_state = load_initial_weights(args.init)
        except (OSError, ValueError) as exc:
            raise SystemExit(str(exc)) from None
        if (args.devices is not None or args.six_trackers) \
                and parse_devices(args.devices, args.six_trackers) != tuple(cfg.devices):
            said = f"--devices {args.devices}" if args.devices is not None else "--six-trackers"
            raise SystemExit(f"{said}: --init {args.init} takes {', '.join(cfg.devices)}")
        if args.arch is not None and args.arch != cfg.arch:
            raise SystemExit(f"--arch {args.arch}: --init {args.init} is a {cfg.arch} model (fine-tuning keeps "
                             f"its backbone; leave out --arch, or train a {args.arch} model without --init)")
        if args.causal and not cfg.causal:
            raise SystemExit(f"--causal: --init {args.init} is not a causal model (it sees future frames; "
                             f"fine-tuning keeps that): leave out --causal, or train a causal model without --init")
        if args.window is not None and args.window != cfg.window:
            from .init_weights import widen_window
            try:
                cfg, init_state = widen_window(cfg, init_state, args.window)
            except ValueError as exc:
                raise SystemExit(str(exc)) from None
        # dropout is a training setting, not part of the exported model: --dropout applies here too
        cfg = dataclasses.replace(cfg, dropout=args.dropout)
    elif ckpt is None:
        devices = parse_devices(args.devices, args.six_trackers)
        cfg = ModelConfig(kind=args.kind, devices=devices, window=args.window or 40, d_model=args.d_model,
                          layers=args.layers, heads=args.heads, ff_mult=args.ff_mult,
                          head_hidden=args.head_hidden, dropout=args.dropout, causal=args.causal,
                          arch=args.arch or "posenet")

    # ---------------------------------------------------------------- data
    try:
        sources = dataset.load_sources(args.sources) if args.sources else [dataset.MotionSource(p) for p in args.bvh]
    except (OSError, ValueError) as exc:
        raise SystemExit(f"--sources: {exc}") from None
    train_files, val_files, per_source, val_is_train = [], [], [], False
    for src in sources:
        files = dataset.build_cache(src, args.cache_dir, workers=args.workers, verbose=not args.quiet)
        tr, va, split = dataset.split_files(files)
        index, _ = dataset.load_index(files)
        train_files += tr
        val_files += va
        val_is_train |= bool(split.get("val_is_train"))
        per_source.append(dict(name=src.label, path=os.path.abspath(src.path), format=index.get("format", "bvh"),
                               options=src.read_options(), licence=dataset.source_licence(src), clips=len(files),
                               frames=int(index["frames"]), hours=round(index["frames"] / index["fps"] / 3600, 3),
                               cache=os.path.dirname(os.path.dirname(files[0])),
                               split=dict(rule=split["rule"], train_clips=len(tr), val_clips=len(va),
                                          train_takes=split["train_takes"], val_takes=split["val_takes"],
                                          train_frames=split["train_frames"], val_frames=split["val_frames"])))
    train_set = dataset.ClipSet.load(train_files)
    val_set = train_set if val_is_train else dataset.ClipSet.load(val_files)
    sampler = dataset.WindowSampler(train_set, window=cfg.window, kind=cfg.kind, devices=cfg.devices,
                                    seed=args.seed, body=cfg.body, augment=aug, balance=args.balance)
    val_batches = dataset.fixed_batches(val_set, args.val_windows, 64, window=cfg.window, kind=cfg.kind,
                                        devices=cfg.devices, seed=args.seed + 12345, body=cfg.body)
    select_batches = None
    if args.select_on:
        sel_files = dataset.build_cache(args.select_on, args.cache_dir, workers=args.workers, verbose=not args.quiet)
        select_batches = dataset.fixed_batches(dataset.ClipSet.load(sel_files), args.val_windows, 64,
                                               window=cfg.window, kind=cfg.kind, devices=cfg.devices,
                                               seed=args.seed + 777, body=cfg.body)
    # fork the batch maker before torch starts its thread pool
    prefetch = dataset.Prefetcher(sampler, args.batch, args.seed, int(ckpt["step"]) if ckpt else 0,
                                  workers=args.data_workers)
    first = per_source[0]
    data_info = dict(source=" + ".join(p["name"] for p in per_source), source_path=first["path"],
                     sources=per_source, cache=first["cache"], clips=sum(p["clips"] for p in per_source),
                     frames=sum(p["frames"] for p in per_source), fps=dataset.MODEL_FPS,
                     split=dict(rule=first["split"]["rule"], train_clips=len(train_files), val_clips=len(val_files),
                                train_takes=sum(p["split"]["train_takes"] for p in per_source),
                                val_takes=sum(p["split"]["val_takes"] for p in per_source),
                                train_frames=sum(p["split"]["train_frames"] for p in per_source),
                                val_frames=sum(p["split"]["val_frames"] for p in per_source),
                                val_is_train=val_is_train),
                     licence=dataset.combined_licence([p["licence"] for p in per_source]),
                     contact_rule=dict(speed_mps=dataset.CONTACT_SPEED, height_m=dataset.CONTACT_HEIGHT),
                     augmentation=dataclasses.asdict(sampler.aug),
                     sampling=dict(balance=sampler.balance,
                                   group_shares={g: round(v, 4) for g, v in sampler.group_shares().items()}),
                     validation=f"{args.val_windows} fixed windows of the held-out takes, no augmentation"
                     + (f"; checkpoints chosen on {os.path.basename(args.select_on)}" if args.select_on else ""))
    split = data_info["split"]
    say(f"data: {data_info['clips']} clips, {data_info['frames']} frames from {data_info['source']}; "
        f"train {len(train_files)} clips / {split['train_frames']} frames, "
        f"val {len(val_files)} clips / {split['val_frames']} frames ({split['val_takes']} takes)")
    if sampler.balance:
        shares = sampler.group_shares()
        say(f"sampling: balance {sampler.balance:g} over {len(shares)} motion classes; windows drawn: "
            + ", ".join(f"{g} {100 * v:.1f} %" for g, v in shares.items()))

    # --------------------------------------------------------------- model
    torch.manual_seed(args.seed)
    model = build_model(cfg)
    opt = torch.optim.AdamW(model.parameters(), lr=args.lr, weight_decay=args.weight_decay)
    step, elapsed, history = 0, 0.0, []
    averaged = None
    if ckpt is not None:
        model.load_state_dict(ckpt["model"])
        opt.load_state_dict(ckpt["optimizer"])
        if args.ema:
            averaged = WeightAverage(model, args.ema)
            if ckpt.get("ema"):
                averaged.load_state_dict(ckpt["ema"])
        step, elapsed, history = int(ckpt["step"]), float(ckpt["elapsed"]), list(ckpt.get("history", []))
        torch.set_rng_state(ckpt["torch_rng"])
        say(f"resumed {ckpt_path} at step {step} ({elapsed / 60:.1f} min trained)")
    elif init_state is not None:
        model.load_state_dict(init_state)
        say(f"initial weights from {args.init}")
    if averaged is None and args.ema:
        averaged = WeightAverage(model, args.ema)
    nparams = count_parameters(model)
    say(f"model: {cfg.kind}, {cfg.arch}, d_model {cfg.d_model}, {cfg.layers} layers, {cfg.heads} heads, window "
        f"{cfg.window}, inputs {list(cfg.devices)}: {nparams:,} parameters; batch {args.batch}, "
        f"{args.threads} threads; loss weights {dict(losses.LAMBDA, **lam)}; plan: "
        + (f"{args.steps} steps" if args.steps else "") + (" / " if args.steps and args.minutes else "")
        + (f"{args.minutes:g} min" if args.minutes else "")
        + (f"; validating the weight average (decay {args.ema:g})" if averaged is not None else ""))

    warmup = args.warmup if not args.steps else min(args.warmup, max(1, args.steps // 20))

    def progress_of(step_, elapsed_):
        p = 0.0
        if args.steps:
            p = max(p, step_ / args.steps)
        if args.minutes:
            p = max(p, elapsed_ / (args.minutes * 60.0))
        return p

    def checkpoint(val):
        _save(ckpt_path, dict(model=model.state_dict(), optimizer=opt.state_dict(), step=step,
                              elapsed=elapsed, config=cfg.to_dict(), args=vars(args),
                              torch_rng=torch.get_rng_state(),
                              data=data_info, history=history, val=val, num_parameters=nparams,
                              ema=averaged.state_dict() if averaged is not None else None,
                              code_version=__version__, saved=time.strftime("%Y-%m-%d %H:%M:%S")))

    def validate():
        """Metrics of the weights the run stands for (the average with --ema); with --ema also the
        raw weights' on the --select-on source, as ``raw_select_*``."""
        with (averaged.applied(model) if averaged is not None else contextlib.nullcontext()):
            m = evaluate(model, val_batches, cfg.kind, cfg.devices, lam=lam)
            sm = evaluate(model, select_batches, cfg.kind, cfg.devices, lam=lam) if select_batches is not None else None
        rec = dict(step=step, minutes=round(elapsed / 60, 2), **{k: round(v, 5) for k, v in m.items()})
        if sm is not None:
            rec.update({f"select_{k}": round(v, 5) for k, v in sm.items()})
            if averaged is not None:
                raw = evaluate(model, select_batches, cfg.kind, cfg.devices, lam=lam)
                rec.update({f"raw_select_{k}": round(raw[k], 5) for k in ("mpjpe_cm", "lower_cm")})
        history.append(rec)
        with open(os.path.join(args.out, "metrics.jsonl"), "a", encoding="utf-8", newline="\n") as f:
            f.write(json.dumps(rec) + "\n")
        bar.newline()
        say(f"[val] step {step} ({elapsed / 60:.1f} min): loss {m['loss']:.4f}  MPJPE {m['mpjpe_cm']:.2f} cm  "
            f"hand {m['hand_cm']:.2f}  upper {m['upper_cm']:.2f}  lower {m['lower_cm']:.2f} cm  "
            f"root {m['root_deg']:.2f} deg  contact acc {m['contact_acc']:.3f}"
            + (f"  | select-on: MPJPE {rec['select_mpjpe_cm']:.2f}  lower {rec['select_lower_cm']:.2f} cm"
               if select_batches is not None else "")
            + (f" (raw weights {rec['raw_select_mpjpe_cm']:.2f}, {rec['raw_select_lower_cm']:.2f})"
               if "raw_select_mpjpe_cm" in rec else ""))
        return rec

    def keep_best(rec):
        """OUT/best.pt: the checkpoint with the lowest MPJPE on the --select-on source."""
        if select_batches is None or rec is None:
            return
        prior = [h["select_mpjpe_cm"] for h in history[:-1] if "select_mpjpe_cm" in h]
        if not prior or rec["select_mpjpe_cm"] < min(prior):
            import shutil
            shutil.copyfile(ckpt_path, os.path.join(args.out, "best.pt.tmp"))
            os.replace(os.path.join(args.out, "best.pt.tmp"), os.path.join(args.out, "best.pt"))

    bar = Progress(not args.quiet)
    model.train()
    t_start = time.time() - elapsed
    last_ckpt = time.time()
    ema, rate, rate_t, rate_s = None, 0.0, time.time(), step
    val = history[-1] if history else None
    interrupted = False
    try:
        while True:
            elapsed = time.time() - t_start
            if (args.steps is not None and step >= args.steps) or (args.minutes and elapsed >= args.minutes * 60.0):
                break
            if args.stop_at is not None and step >= args.stop_at:
                break
            f = lr_factor(progress_of(step, elapsed), step, warmup)
            for g in opt.param_groups:
                g["lr"] = args.lr * f
            batch = losses.to_torch(prefetch.get(step))
            y = model(batch["x"])
            total, terms, _ = losses.compute_loss(y, batch, cfg.kind, cfg.devices, lam=lam)
            opt.zero_grad(set_to_none=True)
            total.backward()
            torch.nn.utils.clip_grad_norm_(model.parameters(), 1.0)
            opt.step()
            if averaged is not None:
                averaged.update(model)
            step += 1
            lv = total.item()
            if not math.isfinite(lv):
                raise SystemExit(f"loss is {lv} at step {step}; terms {terms}")
            ema = lv if ema is None else 0.98 * ema + 0.02 * lv
            now = time.time()
            if now - rate_t > 2.0 or rate == 0.0:       # first estimate at once, then every 2 s
                rate = (step - rate_s) / max(now - rate_t, 1e-6)
                if now - rate_t > 2.0:
                    rate_t, rate_s = now, step
            elapsed = now - t_start
            if rate > 0:
                left = []
                if args.steps is not None:
                    left.append((args.steps - step) / rate)
                if args.minutes:
                    left.append(args.minutes * 60.0 - elapsed)
                eta = _fmt_time(min(left))
            else:
                eta = "?"
            bar.update(f"step {step}" + (f"/{args.steps}" if args.steps else "") + f" | loss {ema:.4f} | "
                       f"{rate:.2f} steps/s | lr {args.lr * f:.2e} | {_fmt_time(elapsed)} elapsed | ETA {eta}")
            if (now - last_ckpt >= args.ckpt_minutes * 60.0) or (args.ckpt_steps and step % args.ckpt_steps == 0):
                val = validate()
                checkpoint(val)
                keep_best(val)
                last_ckpt = time.time()
    except KeyboardInterrupt:
        interrupted = True
        bar.newline()
        say(f"interrupted at step {step}: saving the checkpoint (--resume continues)")
    finally:
        prefetch.close()
    elapsed = time.time() - t_start
    bar.newline()
    fresh = not history or history[-1]["step"] != step
    if fresh:
        val = validate()
    checkpoint(val)
    if fresh:
        keep_best(val)
    say(f"done: {step} steps in {elapsed / 60:.1f} min; checkpoint {ckpt_path}")
    return dict(step=step, elapsed=elapsed, val=val, checkpoint=ckpt_path, num_parameters=nparams,
                interrupted=interrupted)


if __name__ == "__main__":
    main()
