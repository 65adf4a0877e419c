"""NavRL's released policy without PyTorch: a checkpoint reader and a numpy forward pass.

The NavRL authors publish their trained PPO policy as a PyTorch checkpoint (a zip file with a
pickled ``state_dict`` and raw tensor storages). ft-sitl does not ship it (the user supplies
it, see :mod:`~ft_sitl.navigation.learned.navrl`) and does not depend on PyTorch:
:func:`load_checkpoint` reads the zip with a restricted unpickler that builds numpy arrays
and refuses every other object (a checkpoint cannot run code here), and :class:`NavRLPolicy`
evaluates the network:

* lidar CNN on the 36 x 4 "range deficit" image: Conv(1->4, 5x3, pad 2x1), ELU,
  Conv(4->16, 5x3, stride 2x1, pad 2x1), ELU, Conv(16->16, 5x3, stride 2x2, pad 2x1), ELU,
  flatten (288), Linear 128, LayerNorm;
* dynamic-obstacle MLP on 5 x 10 inputs: Linear 128, LeakyReLU, LayerNorm, Linear 64,
  LeakyReLU, LayerNorm;
* trunk on [cnn 128, state 8, dynamic 64]: (Linear 256, LeakyReLU, LayerNorm) x 2;
* Beta actor: alpha, beta = 1 + softplus(linear) + 1e-6; the deployed action is the mean
  alpha / (alpha + beta) in [0, 1] per goal-frame axis.

Every shape is checked against this architecture when the weights are loaded; a mismatch
names the tensor.
"""

from __future__ import annotations

import io
import pickle
import zipfile
from collections import OrderedDict
from pathlib import Path

import numpy as np
from numba import njit

LIDAR_H = 36  # horizontal beams, 10 deg apart
LIDAR_V = 4  # vertical beams: -10, 0, 10, 20 deg
STATE_DIM = 8
DYN_OBS = 5
DYN_DIM = 10

_DTYPES = {
    "FloatStorage": np.float32, "DoubleStorage": np.float64, "HalfStorage": np.float16,
    "BFloat16Storage": None, "LongStorage": np.int64, "IntStorage": np.int32,
    "ShortStorage": np.int16, "CharStorage": np.int8, "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}

#: tensor name -> shape of the released NavRL actor (critic and value norm are not needed)
EXPECTED_SHAPES: dict[str, tuple[int, ...]] = {
    "feature_extractor.module.0.module.0.weight": (4, 1, 5, 3),
    "feature_extractor.module.0.module.0.bias": (4,),
    "feature_extractor.module.0.module.2.weight": (16, 4, 5, 3),
    "feature_extractor.module.0.module.2.bias": (16,),
    "feature_extractor.module.0.module.4.weight": (16, 16, 5, 3),
    "feature_extractor.module.0.module.4.bias": (16,),
    "feature_extractor.module.0.module.7.weight": (128, 288),
    "feature_extractor.module.0.module.7.bias": (128,),
    "feature_extractor.module.0.module.8.weight": (128,),
    "feature_extractor.module.0.module.8.bias": (128,),
    "feature_extractor.module.1.module.1.0.weight": (128, 50),
    "feature_extractor.module.1.module.1.0.bias": (128,),
    "feature_extractor.module.1.module.1.2.weight": (128,),
    "feature_extractor.module.1.module.1.2.bias": (128,),
    "feature_extractor.module.1.module.1.3.weight": (64, 128),
    "feature_extractor.module.1.module.1.3.bias": (64,),
    "feature_extractor.module.1.module.1.5.weight": (64,),
    "feature_extractor.module.1.module.1.5.bias": (64,),
    "feature_extractor.module.3.module.0.weight": (256, 200),
    "feature_extractor.module.3.module.0.bias": (256,),
    "feature_extractor.module.3.module.2.weight": (256,),
    "feature_extractor.module.3.module.2.bias": (256,),
    "feature_extractor.module.3.module.3.weight": (256, 256),
    "feature_extractor.module.3.module.3.bias": (256,),
    "feature_extractor.module.3.module.5.weight": (256,),
    "feature_extractor.module.3.module.5.bias": (256,),
    "actor.module.0.module.alpha_layer.weight": (3, 256),
    "actor.module.0.module.alpha_layer.bias": (3,),
    "actor.module.0.module.beta_layer.weight": (3, 256),
    "actor.module.0.module.beta_layer.bias": (3,),
}


class CheckpointError(ValueError):
    """A file that is not a readable NavRL checkpoint; the message says what is wrong."""


class _Storage:
    def __init__(self, dtype, key: str, numel: int):
        self.dtype, self.key, self.numel = dtype, key, numel


def _rebuild_tensor(storage, offset, size, stride, *_rest):
    if not isinstance(storage, np.ndarray):
        raise CheckpointError("tensor without a storage")
    size, stride = tuple(int(s) for s in size), tuple(int(s) for s in stride)
    if any(s < 0 for s in size) or any(s < 0 for s in stride) or offset < 0:
        raise CheckpointError(f"tensor with a negative size/stride/offset: {size} {stride}")
    last = offset + sum((n - 1) * s for n, s in zip(size, stride)) if all(size) else offset
    if all(size) and last >= storage.size:
        raise CheckpointError(f"tensor {size} with stride {stride} at offset {offset} runs "
                              f"past its storage of {storage.size} elements")
    item = storage.itemsize
    view = np.lib.stride_tricks.as_strided(storage[offset:] if storage.size else storage,
                                           shape=size, strides=[s * item for s in stride],
                                           writeable=False)
    return np.array(view)


def _rebuild_parameter(data, *_rest):
    return data


class _Unpickler(pickle.Unpickler):
    """Builds numpy arrays from torch's tensor records and refuses every other global."""

    def __init__(self, fp, zf: zipfile.ZipFile, prefix: str, byteorder: str):
        super().__init__(fp)
        self._zf, self._prefix, self._order = zf, prefix, byteorder
        self._loaded: dict[str, np.ndarray] = {}

    def find_class(self, module, name):
        if module == "collections" and name == "OrderedDict":
            return OrderedDict
        if module == "torch._utils" and name == "_rebuild_tensor_v2":
            return _rebuild_tensor
        if module == "torch._utils" and name == "_rebuild_parameter":
            return _rebuild_parameter
        if module == "torch" and name in _DTYPES:
            if _DTYPES[name] is None:
                raise CheckpointError(f"tensor type torch.{name} is not supported")
            return ("dtype", _DTYPES[name])
        raise CheckpointError(f"the checkpoint refers to {module}.{name}, which a NavRL "
                              "weights file does not contain (refused: only tensors and "
                              "dictionaries are read)")

    def persistent_load(self, pid):
        if not (isinstance(pid, tuple) and len(pid) >= 5 and pid[0] == "storage"):
            raise CheckpointError(f"unexpected persistent record {pid!r:.80}")
        kind, key, numel = pid[1], str(pid[2]), int(pid[4])
        if not (isinstance(kind, tuple) and kind[0] == "dtype"):
            raise CheckpointError(f"storage {key}: unknown storage type {kind!r:.60}")
        dtype = np.dtype(kind[1]).newbyteorder("<" if self._order == "little" else ">")
        if key not in self._loaded:
            name = f"{self._prefix}/data/{key}"
            try:
                raw = self._zf.read(name)
            except KeyError:
                raise CheckpointError(f"storage record {name} is missing") from None
            if len(raw) != numel * dtype.itemsize:
                raise CheckpointError(f"storage {name}: {len(raw)} bytes, expected "
                                      f"{numel} x {dtype.itemsize}")
            self._loaded[key] = np.frombuffer(raw, dtype=dtype).astype(dtype.newbyteorder("="))
        return self._loaded[key]


def load_checkpoint(path) -> dict[str, np.ndarray]:
    """The tensors of a PyTorch zip checkpoint as ``name -> ndarray``."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{path}: no such file")
    try:
        zf = zipfile.ZipFile(path)
    except zipfile.BadZipFile:
        raise CheckpointError(f"{path}: not a PyTorch zip checkpoint (legacy pickle-only "
                              "checkpoints are not supported)") from None
    with zf:
        pkls = [n for n in zf.namelist() if n.endswith("/data.pkl")]
        if len(pkls) != 1:
            raise CheckpointError(f"{path}: expected one */data.pkl record, found {len(pkls)}")
        prefix = pkls[0][: -len("/data.pkl")]
        order = "little"
        if f"{prefix}/byteorder" in zf.namelist():
            order = zf.read(f"{prefix}/byteorder").decode("ascii", "replace").strip()
            if order not in ("little", "big"):
                raise CheckpointError(f"{path}: unknown byte order {order!r}")
        try:
            obj = _Unpickler(io.BytesIO(zf.read(pkls[0])), zf, prefix, order).load()
        except CheckpointError as exc:
            raise CheckpointError(f"{path}: {exc}") from None
        except Exception as exc:  # noqa: BLE001 - a corrupt pickle raises many types
            raise CheckpointError(f"{path}: unreadable checkpoint ({type(exc).__name__}: "
                                  f"{exc})") from None
    if not isinstance(obj, dict):
        raise CheckpointError(f"{path}: the checkpoint holds a {type(obj).__name__}, not a "
                              "state dict")
    bad = [k for k, v in obj.items() if not isinstance(v, np.ndarray)]
    if bad:
        raise CheckpointError(f"{path}: entries that are not tensors: {', '.join(bad[:5])}")
    return dict(obj)


# --- the network ---------------------------------------------------------------------------

@njit(cache=True)
def _conv2d_kernel(x, w, b, sh, sw, ph, pw):
    c_in, h, wd = x.shape
    c_out, _, kh, kw = w.shape
    ho = (h + 2 * ph - kh) // sh + 1
    wo = (wd + 2 * pw - kw) // sw + 1
    out = np.empty((c_out, ho, wo))
    for o in range(c_out):
        for i in range(ho):
            for j in range(wo):
                acc = 0.0
                for c in range(c_in):
                    for a in range(kh):
                        r = i * sh + a - ph
                        if r < 0 or r >= h:
                            continue
                        for e in range(kw):
                            q = j * sw + e - pw
                            if 0 <= q < wd:
                                acc += x[c, r, q] * w[o, c, a, e]
                out[o, i, j] = acc + b[o]
    return out


def _conv2d(x, w, b, stride, pad):
    """x (C, H, W), w (O, C, kh, kw) -> (O, H', W'), zero padding, cross-correlation."""
    return _conv2d_kernel(np.ascontiguousarray(x, dtype=np.float64), w, b,
                          int(stride[0]), int(stride[1]), int(pad[0]), int(pad[1]))


def _elu(x):
    return np.where(x > 0, x, np.expm1(np.minimum(x, 0.0)))


def _leaky(x):
    return np.where(x > 0, x, 0.01 * x)


def _layer_norm(x, g, b, eps=1e-5):
    mu = x.mean()
    var = ((x - mu) ** 2).mean()
    return (x - mu) / np.sqrt(var + eps) * g + b


def _softplus(x):
    return np.where(x > 20.0, x, np.log1p(np.exp(np.minimum(x, 20.0))))


class NavRLPolicy:
    """The NavRL actor in numpy (float64)."""

    def __init__(self, weights: dict[str, np.ndarray], source: str = "weights"):
        missing = [k for k in EXPECTED_SHAPES if k not in weights]
        if missing:
            raise CheckpointError(f"{source}: not a NavRL policy: missing "
                                  f"{', '.join(missing[:4])}"
                                  + (f" and {len(missing) - 4} more" if len(missing) > 4
                                     else ""))
        for k, shape in EXPECTED_SHAPES.items():
            if tuple(weights[k].shape) != shape:
                raise CheckpointError(f"{source}: {k} has shape {tuple(weights[k].shape)}, "
                                      f"the NavRL architecture needs {shape}")
            if not np.all(np.isfinite(weights[k])):
                raise CheckpointError(f"{source}: {k} holds non-finite values")
        self.w = {k: np.asarray(weights[k], dtype=np.float64) for k in EXPECTED_SHAPES}

    @classmethod
    def from_checkpoint(cls, path) -> NavRLPolicy:
        return cls(load_checkpoint(path), source=str(path))

    def features(self, state, lidar, dynamic) -> np.ndarray:
        w = self.w
        f = "feature_extractor.module."
        x = np.asarray(lidar, dtype=np.float64).reshape(1, LIDAR_H, LIDAR_V)
        x = _elu(_conv2d(x, w[f + "0.module.0.weight"], w[f + "0.module.0.bias"], (1, 1),
                         (2, 1)))
        x = _elu(_conv2d(x, w[f + "0.module.2.weight"], w[f + "0.module.2.bias"], (2, 1),
                         (2, 1)))
        x = _elu(_conv2d(x, w[f + "0.module.4.weight"], w[f + "0.module.4.bias"], (2, 2),
                         (2, 1)))
        x = w[f + "0.module.7.weight"] @ x.reshape(-1) + w[f + "0.module.7.bias"]
        cnn = _layer_norm(x, w[f + "0.module.8.weight"], w[f + "0.module.8.bias"])
        d = np.asarray(dynamic, dtype=np.float64).reshape(-1)
        d = _leaky(w[f + "1.module.1.0.weight"] @ d + w[f + "1.module.1.0.bias"])
        d = _layer_norm(d, w[f + "1.module.1.2.weight"], w[f + "1.module.1.2.bias"])
        d = _leaky(w[f + "1.module.1.3.weight"] @ d + w[f + "1.module.1.3.bias"])
        d = _layer_norm(d, w[f + "1.module.1.5.weight"], w[f + "1.module.1.5.bias"])
        h = np.concatenate([cnn, np.asarray(state, dtype=np.float64).reshape(-1), d])
        for lin, ln in (("0", "2"), ("3", "5")):
            h = _leaky(w[f + f"3.module.{lin}.weight"] @ h + w[f + f"3.module.{lin}.bias"])
            h = _layer_norm(h, w[f + f"3.module.{ln}.weight"], w[f + f"3.module.{ln}.bias"])
        return h

    def beta_parameters(self, state, lidar, dynamic) -> tuple[np.ndarray, np.ndarray]:
        h = self.features(state, lidar, dynamic)
        a = "actor.module.0.module."
        alpha = 1.0 + _softplus(self.w[a + "alpha_layer.weight"] @ h
                                + self.w[a + "alpha_layer.bias"]) + 1e-6
        beta = 1.0 + _softplus(self.w[a + "beta_layer.weight"] @ h
                               + self.w[a + "beta_layer.bias"]) + 1e-6
        return alpha, beta

    def mean_action(self, state, lidar, dynamic) -> np.ndarray:
        """The deployed action: the Beta mean in [0, 1] per goal-frame axis."""
        for name, v, n in (("state", state, STATE_DIM), ("lidar", lidar, LIDAR_H * LIDAR_V),
                           ("dynamic", dynamic, DYN_OBS * DYN_DIM)):
            if np.size(v) != n:
                raise ValueError(f"{name}: {np.size(v)} values, the policy takes {n}")
        alpha, beta = self.beta_parameters(state, lidar, dynamic)
        return alpha / (alpha + beta)
