"""Load the shipped ONNX pose network and read its contract.  No bpy, no torch.

The contract is JSON stored in the ONNX file's ``metadata_props`` under
``manikin_contract`` (written by ``blender_manikin.training.export``): input
and output names and shapes, fps, window, input devices, joint names, output
blocks and normalisation constants.  The add-on reads these instead of
hard-coding them and refuses a model whose contract does not match the code.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass

import numpy as np

from . import features
from .skeleton import JOINT_NAMES

MODELS_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "models")
DEFAULT_MODEL = os.path.join(MODELS_DIR, "manikin_s.onnx")
CONTRACT_KEY = "manikin_contract"


class ModelError(RuntimeError):
    """The model file is missing, unreadable or does not match this code."""


def _import_onnxruntime():
    """onnxruntime, or :class:`.onnx_runtime_loader.OnnxRuntimeUnavailable` with a message for the user."""
    from . import onnx_runtime_loader
    return onnx_runtime_loader.import_onnxruntime()


@dataclass
class Contract:
    kind: str
    fps: float
    window: int
    devices: tuple
    input_name: str
    output_name: str
    input_dim: int
    output_dim: int
    raw: dict

    @property
    def trained_mirrored(self):
        """Whether the model was trained on left/right mirrored windows (its contract records a
        mirror augmentation), so that a mirrored window is as familiar to it as a plain one."""
        aug = (self.raw.get("training_data") or {}).get("augmentation") or {}
        return bool(aug.get("mirror"))

    @property
    def arch(self):
        """The backbone the model was trained with (``train --arch``: ``posenet``, ``dap``), None
        where the contract does not say."""
        return (self.raw.get("architecture") or {}).get("arch")

    @property
    def causal(self):
        """Whether the model attends to past frames only (``train --causal``, a live variant): it is
        run with one window per frame that ends at that frame (:func:`.pipeline.run_network`)."""
        return bool(self.raw.get("causal"))

    @property
    def body(self):
        """Whether the model takes :data:`features.BODY_FEATURES` (the performer's proportions)."""
        return bool(self.raw.get("body_features"))

    @classmethod
    def from_json(cls, text, path="<model>"):
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise ModelError(f"{path}: the '{CONTRACT_KEY}' metadata is not valid JSON ({exc})") from exc
        try:
            c = cls(kind=d["kind"], fps=float(d["fps"]), window=int(d["window"]),
                    devices=tuple(d["input_devices"]), input_name=d["input_name"],
                    output_name=d["output_name"], input_dim=int(d["input_shape"][-1]),
                    output_dim=int(d["output_shape"][-1]), raw=d)
        except KeyError as exc:
            raise ModelError(f"{path}: model contract lacks the field {exc}") from exc
        c.check(path)
        return c

    def check(self, path):
        """Raise :class:`ModelError` when the contract disagrees with this code."""
        problems = []
        if self.kind not in features.OUTPUT_BLOCKS:
            problems.append(f"unknown model kind {self.kind!r}")
        else:
            blocks = [tuple(b) for b in self.raw.get("output_blocks", [])]
            if blocks and blocks != [tuple(b) for b in features.OUTPUT_BLOCKS[self.kind]]:
                problems.append(f"output blocks {blocks} differ from the code's")
            if self.output_dim != features.output_dim(self.kind):
                problems.append(f"output size {self.output_dim} != {features.output_dim(self.kind)}")
        body = self.raw.get("body_features") or []
        if body and tuple(body) != features.BODY_FEATURES:
            problems.append(f"body features {body} differ from the code's {list(features.BODY_FEATURES)}")
        norm = self.raw.get("body_normalisation") or {}
        if body and (abs(float(norm.get("scale", -1)) - features.BODY_SCALE) > 1e-9
                     or not np.allclose(norm.get("reference", []), features.BODY_REFERENCE, atol=1e-6)):
            problems.append("body feature normalisation differs from the code's")
        if self.input_dim != features.input_dim(self.devices, body=bool(body)):
            problems.append(f"input size {self.input_dim} != {features.input_dim(self.devices, body=bool(body))}")
        if tuple(self.raw.get("joint_names", JOINT_NAMES)) != tuple(JOINT_NAMES):
            problems.append("joint names differ from the 22-joint body")
        vs = self.raw.get("normalisation", {}).get("vel_scale", features.VEL_SCALE)
        if abs(float(vs) - features.VEL_SCALE) > 1e-12:
            problems.append(f"velocity scale {vs} != {features.VEL_SCALE}")
        if problems:
            raise ModelError(f"{path}: model contract does not match this add-on: " + "; ".join(problems))


#: windows per onnxruntime call: small batches stay in the CPU caches.  The HDM05 set solved as
#: one take (17,878 frames, 2 threads; best of 5): 16 / 32 / 64 / 128 / 256 windows per call,
#: the network stage 0.68 / 0.65 / 0.69 / 0.74 / 0.80 s
RUN_BATCH = 32


class ModelRunner:
    """An onnxruntime session plus its contract.

    ``predict(x)`` takes ``(B, W, F_in)`` float32 and returns
    ``(B, W, F_out)`` float32, in batches of ``batch`` windows (default :data:`RUN_BATCH`).
    """

    def __init__(self, path=None, threads=None, batch=None):
        path = path or default_model_path()
        if not os.path.isfile(path):
            raise ModelError(f"pose model not found: {path} (reinstall the add-on, or train one with "
                             "'python -m blender_manikin.training.train')")
        ort = _import_onnxruntime()
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = int(threads or min(4, os.cpu_count() or 1))
        opts.inter_op_num_threads = 1
        # no memory arena: it would keep the largest batch's buffers for the process's lifetime
        # (about 100 MB after a long take, held while Blender keys it); no speed cost measured
        opts.enable_cpu_mem_arena = False
        try:
            self.session = ort.InferenceSession(path, sess_options=opts, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own exception types
            raise ModelError(f"{path}: onnxruntime could not load the model ({exc})") from exc
        meta = self.session.get_modelmeta().custom_metadata_map
        if CONTRACT_KEY not in meta:
            raise ModelError(f"{path}: no '{CONTRACT_KEY}' metadata; not a blender_manikin model")
        self.contract = Contract.from_json(meta[CONTRACT_KEY], path)
        self.path = path
        self.batch = int(batch or RUN_BATCH)

    @property
    def num_parameters(self):
        return int(self.contract.raw.get("num_parameters", 0))

    def predict(self, x):
        x = np.ascontiguousarray(x, dtype=np.float32)
        out = []
        for i in range(0, x.shape[0], self.batch):
            out.append(self.session.run([self.contract.output_name],
                                        {self.contract.input_name: x[i:i + self.batch]})[0])
        if not out:
            return np.zeros((0, x.shape[1], self.contract.output_dim), np.float32)
        return np.concatenate(out, 0)


_CACHE = {}


def default_model_path():
    """``$BLENDER_MANIKIN_MODEL`` when set (a model you trained), else the shipped model."""
    return os.environ.get("BLENDER_MANIKIN_MODEL") or DEFAULT_MODEL


def load_model(path=None, threads=None) -> ModelRunner:
    """Cached :class:`ModelRunner` for ``path`` (default: :func:`default_model_path`) with
    ``threads`` onnxruntime threads (default: up to 4)."""
    path = os.path.abspath(path or default_model_path())
    key = (path, threads)
    if key not in _CACHE:
        _CACHE[key] = ModelRunner(path, threads=threads)
    return _CACHE[key]
