"""An exponential moving average of a model's weights, for training.

The weights a run ships are often better as an average over its last few
thousand optimizer steps than as the last step alone: the average smooths the
step-to-step noise of small batches. ``train.py --ema DECAY`` keeps one; the
run then validates, selects (``best.pt``) and exports the averaged weights,
while the optimizer goes on updating the raw ones. (On the shipped stage-2 recipe, whose cosine
decay ends at 5 % of the rate, it changed nothing: HDM05 10.11 cm averaged against 10.08 raw at
the end; the model card has the run.)

A checkpoint keeps both: ``"model"`` (raw, what the optimizer resumes) and
``"ema"`` (:meth:`WeightAverage.state_dict`). :func:`trained_weights` is the one
place that picks the weights a checkpoint stands for.
"""
from __future__ import annotations

import contextlib


class WeightAverage:
    """``avg = d * avg + (1 - d) * weights`` after every optimizer step.

    decay: the long-run ``d`` in (0, 1), e.g. 0.999 (an average over about the
    last 1,000 steps). Early on ``d`` is ``min(decay, (1 + n) / (10 + n))`` after
    ``n`` updates, so the average is not dragged towards the starting weights.
    Floating-point tensors (parameters and buffers) are averaged in float32;
    other buffers are copied.
    """

    def __init__(self, model, decay: float):
        if not 0.0 < decay < 1.0:
            raise ValueError(f"weight average decay {decay!r}: must be between 0 and 1")
        self.decay = float(decay)
        self.updates = 0
        self.weights = {k: v.detach().clone().float() if v.is_floating_point() else v.detach().clone()
                        for k, v in model.state_dict().items()}

    def rate(self) -> float:
        """The ``d`` the next :meth:`update` uses."""
        return min(self.decay, (1.0 + self.updates) / (10.0 + self.updates))

    def update(self, model) -> None:
        import torch
        d = self.rate()
        with torch.no_grad():
            for k, v in model.state_dict().items():
                avg = self.weights[k]
                if avg.is_floating_point():
                    avg.mul_(d).add_(v.detach().float(), alpha=1.0 - d)
                else:
                    avg.copy_(v)
        self.updates += 1

    @contextlib.contextmanager
    def applied(self, model):
        """Run the block with the averaged weights in ``model``; the raw ones come back after."""
        raw = {k: v.detach().clone() for k, v in model.state_dict().items()}
        model.load_state_dict(self.weights)
        try:
            yield model
        finally:
            model.load_state_dict(raw)

    def state_dict(self) -> dict:
        return dict(decay=self.decay, updates=self.updates, weights=self.weights)

    def load_state_dict(self, state: dict) -> None:
        self.decay = float(state["decay"])
        self.updates = int(state["updates"])
        self.weights = {k: v.clone() for k, v in state["weights"].items()}


def trained_weights(ckpt: dict) -> dict:
    """The state dict a training checkpoint stands for: its weight average when the run kept
    one (``--ema``), else the optimizer's weights."""
    avg = ckpt.get("ema")
    return avg["weights"] if avg else ckpt["model"]
