"""A design-view policy's actor read from its file in NumPy, without torch.

A stable-baselines3 zip keeps the network's weights in ``policy.pth``, torch's own zip of
a pickled state dict whose tensors point at raw little-endian storages (``data/0``, ...).
:func:`read_actor` unpickles that dict with an unpickler that builds only the dict and
its tensors (as NumPy arrays: the same bytes, so the same float32 weights torch holds)
and refuses every other object, so a policy file cannot run code when it is read.  The
actor is the ``MlpPolicy`` of MaskablePPO on a flat Box: its ``policy_net`` Linear layers,
each followed by sb3's default activation, ``tanh``, then ``action_net``.
"""

from __future__ import annotations

import io
import itertools
import json
import pickle
import zipfile
from collections import OrderedDict
from dataclasses import dataclass
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Any

import numpy as np

#: The policy classes whose actor :func:`read_actor` reads (``data``'s ``policy_class``).
ACTOR_CRITIC_MODULES: tuple[str, ...] = ("sb3_contrib.common.maskable.policies",)
#: Torch's storage types in a state dict and their NumPy dtypes.
STORAGE_DTYPES: dict[str, str] = {"FloatStorage": "<f4", "DoubleStorage": "<f8",
                                  "HalfStorage": "<f2", "LongStorage": "<i8",
                                  "IntStorage": "<i4", "BoolStorage": "?"}


@dataclass(frozen=True)
class ActorWeights:
    """The actor's layers, input to output: ``weights[i]`` (out, in) and ``biases[i]``
    (out,), float32; every layer but the last is followed by ``tanh``."""

    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]

    def logits(self, observation: np.ndarray) -> np.ndarray:
        """The action logits (float32) of one flat ``observation``: torch's float32
        arithmetic to its rounding (a matrix product may sum in another order)."""
        x = np.asarray(observation, dtype=np.float32)
        last = len(self.weights) - 1
        for k, (weight, bias) in enumerate(zip(self.weights, self.biases, strict=True)):
            x = weight @ x + bias
            if k < last:
                x = np.tanh(x)
        return x

    @cached_property
    def fused(self) -> tuple[tuple[np.ndarray, np.ndarray], ...]:
        """Each layer's weights transposed (in, out) and its bias, float64, contiguous:
        :meth:`logits_many`'s operands, made once per file."""
        return tuple((np.ascontiguousarray(w.T, dtype=np.float64), b.astype(np.float64))
                     for w, b in zip(self.weights, self.biases, strict=True))

    def logits_many(self, observations: np.ndarray) -> np.ndarray:
        """The action logits (N, actions) of ``N`` flat float32 observations (N, in) in one
        pass: a matrix product per layer for all of them, in float64 from the float32
        weights.  A row's logits do not depend on the others' to float64's rounding
        (a product of more rows may sum in another order), so a machine's choice is the
        same deciding alone or in a chunk, unless two logits tie within 1e-15 of each
        other (float32 would leave ties of 1e-7)."""
        return self._last64(self._hidden(observations))

    def _hidden(self, observations: np.ndarray) -> np.ndarray:
        """The last hidden layer's values (N, width), float64, of flat ``observations``."""
        x = np.asarray(observations, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != self.weights[0].shape[1]:
            raise ValueError(f"observations are (N, {self.weights[0].shape[1]}), got "
                             f"{x.shape}")
        # The design view's observation is mostly its stands' one-hots (about 33 of 272
        # inputs are non-zero over a chunk): the first layer multiplies only the columns
        # some row reads, the same sums but for their zero terms.  A chunk of machines
        # played alike decides on one row, whose non-zero inputs are found directly (as
        # flags: NumPy finds the non-zero flags of a row four times faster than its
        # non-zero floats).
        used = (x[0] != 0 if len(x) == 1 else x.any(axis=0)).nonzero()[0]
        (first, bias), *rest = self.fused
        x = np.matmul(x.take(used, axis=1).astype(np.float64), first.take(used, axis=0))
        x += bias
        np.tanh(x, out=x)
        for weight, bias in rest[:-1]:
            x = np.matmul(x, weight)
            x += bias
            np.tanh(x, out=x)
        return x

    def _last64(self, hidden: np.ndarray) -> np.ndarray:
        """The logits (N, actions), float64, of the last hidden layer's values."""
        weight, bias = self.fused[-1]
        x = hidden @ weight
        x += bias
        return x

    @cached_property
    def _open_lasts(self) -> OrderedDict[bytes, OpenLast]:
        """:meth:`open_last`'s blocks, the last :data:`OPEN_LASTS_KEPT` used first."""
        return OrderedDict()

    def open_last(self, open_: np.ndarray) -> OpenLast:
        """The last layer of the actions ``open_`` (actions,) bool, as :meth:`choose_many`
        multiplies it, kept for the next states of the same open actions (a state's stands
        and clock open them: they change at a re-mount and near the budget's end)."""
        key = open_.tobytes()
        kept = self._open_lasts
        block = kept.get(key)
        if block is None:
            block = kept[key] = OpenLast.of(self.weights[-1], self.biases[-1], open_,
                                            self.bounds)
            if len(kept) > OPEN_LASTS_KEPT:
                kept.popitem(last=False)
        else:
            kept.move_to_end(key)
        return block

    @cached_property
    def bounds(self) -> np.ndarray:
        """Each action's bound of its float32 logit's distance from :meth:`logits_many`'s
        (:func:`last_layer_bounds`), made once per file."""
        return last_layer_bounds(self.weights[-1], self.biases[-1])

    def choose_many(self, observations: np.ndarray, masks: np.ndarray,
                    noise: np.ndarray | None = None, states: np.ndarray | None = None
                    ) -> np.ndarray:
        """Each row's most likely open action (N,): the arg-max over ``masks`` (N, actions)
        of :meth:`logits_many` (plus ``noise`` (N, actions), a draw's), the same choice.
        With ``states`` (N,), the observations and masks are those of G distinct states
        (G, ...) and row ``k``'s are state ``states[k]``'s: the network runs once per state,
        and the draws' noise is each row's.

        The hidden layers are :meth:`logits_many`'s, float64; the last, most of the
        arithmetic (1735 actions on the prototype), is found in float32 and only for the
        actions open in some row (their block of the layer kept for the next states of
        the same open actions, :meth:`open_last`).  A row's choice stands where its best
        open logit leads every other by more than its action's bound and the largest
        action's bound of their float32 logits' distance from float64's
        (:func:`last_layer_bounds`, plus the rounding of a draw's noise); any other row is
        decided by its float64 logits, so that a row is never decided otherwise than
        :meth:`logits_many` decides it (a tie within the bound costs that row a float64
        pass)."""
        hidden = self._hidden(observations)
        one = len(hidden) == 1
        if masks.shape != (len(hidden), self.weights[-1].shape[0]) or not (
                masks[0].any() if one else masks.any(axis=1).all()):
            raise ValueError(f"masks are (N, {self.weights[-1].shape[0]}) with an open action "
                             f"in every row, got {masks.shape}")
        if states is not None and (np.ndim(states) != 1 or len(states) == 0 or not (
                0 <= np.min(states) and np.max(states) < len(hidden))):
            raise ValueError(f"states are N indices of the {len(hidden)} observations' rows, "
                             f"got {states!r}")
        # One state's open actions are all the open actions.
        last = self.open_last(masks[0] if one else masks.any(axis=0))
        open_ = last.actions
        # float32 products, then float64 sums with the bias (each float32 exactly widened).
        logits = np.add(np.matmul(hidden.astype(np.float32), last.weight), last.bias)
        if states is not None:
            logits, masks, hidden = logits[states], masks[states], hidden[states]
        if noise is not None:
            logits += noise[:, open_]
        # A value with a draw's noise added is rounded once more (float64's half ulp each
        # of the two compared, both at most the row's largest open logit).
        rounding = 4 * 2.0**-53 * 2 * np.abs(logits).max(axis=1)
        if not one:
            logits[~masks[:, open_]] = -np.inf
        rows = np.arange(len(logits))
        top = logits.argmax(axis=1)
        best = logits.max(axis=1)
        logits[rows, top] = -np.inf
        chosen = open_.take(top)
        # The runner-up's bound is at most the largest of any action's.
        slack = last.bounds.take(top) + last.largest + rounding
        close = (best - logits.max(axis=1) <= slack).nonzero()[0]
        if close.size:
            exact = self._last64(hidden[close])
            if noise is not None:
                exact += noise[close]
            chosen[close] = np.argmax(np.where(masks[close], exact, -np.inf), axis=1)
        return chosen


#: How many open actions' last layers :meth:`ActorWeights.open_last` keeps (each about
#: 0.2 MB on the shipped one-hour policy, about 430 open actions of 1735 a state; a
#: chunk's states take a few dozen sets of open actions an episode).
OPEN_LASTS_KEPT: int = 16


@dataclass(frozen=True)
class OpenLast:
    """The last layer of a set of open actions: their indices (O,), their float32 weights
    transposed (in, O), contiguous, their biases (O,) in float64, their bounds (O,)
    (:func:`last_layer_bounds`) and the largest bound of all actions (the runner-up's,
    open or not, is at most that)."""

    actions: np.ndarray
    weight: np.ndarray
    bias: np.ndarray
    bounds: np.ndarray
    largest: float

    @classmethod
    def of(cls, weight: np.ndarray, bias: np.ndarray, open_: np.ndarray,
           bounds: np.ndarray) -> OpenLast:
        """The block of a last layer ``weight`` (out, in), ``bias`` (out,) and its actions'
        ``bounds`` (out,), for the actions ``open_`` (out,) bool."""
        actions = np.flatnonzero(open_)
        return cls(actions, np.ascontiguousarray(weight[actions].T),
                   bias[actions].astype(np.float64), bounds[actions], float(bounds.max()))


def last_layer_bounds(weight: np.ndarray, bias: np.ndarray) -> np.ndarray:
    """Each action's bound (out,) of the distance between its logit found in float32 from
    float64 hidden values and its float64 logit, for a last layer ``weight`` (out, in),
    ``bias`` (out,) of float32 numbers after ``tanh`` (inputs at most 1): Higham's
    ``gamma_n = n u / (1 - n u)`` of a sum of ``in`` rounded products and the bias (any
    order of summation), with the rounding of each input to float32 (``u`` each), in
    float32 and in float64 (``u`` = 2^-24 and 2^-53)."""
    sizes = np.sum(np.abs(weight), axis=1, dtype=np.float64) + np.abs(bias.astype(np.float64))
    terms = weight.shape[1] + 1
    return sum((_gamma(terms, unit) + unit) * sizes for unit in (2.0**-24, 2.0**-53))


def _gamma(n: int, unit: float) -> float:
    """Higham's ``gamma_n``: the relative error bound of a sum of ``n`` rounded terms in a
    precision of unit roundoff ``unit``."""
    return n * unit / (1 - n * unit)


class _StateDictUnpickler(pickle.Unpickler):
    """Unpickles torch's ``data.pkl`` of a state dict into NumPy arrays: the dict, the
    tensor rebuilder and the storage types, nothing else."""

    def __init__(self, data: bytes, archive: zipfile.ZipFile, prefix: str) -> None:
        super().__init__(io.BytesIO(data))
        self.archive, self.prefix = archive, prefix

    def find_class(self, module: str, name: str) -> Any:
        if (module, name) == ("collections", "OrderedDict"):
            return OrderedDict
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return _rebuild_tensor
        if module == "torch" and name in STORAGE_DTYPES:
            return STORAGE_DTYPES[name]
        raise pickle.UnpicklingError(f"a state dict holds no {module}.{name}")

    def persistent_load(self, pid: Any) -> np.ndarray:
        kind, dtype, key, _location, _count = pid
        if kind != "storage" or dtype not in STORAGE_DTYPES.values():
            raise pickle.UnpicklingError(f"a state dict holds no storage {pid!r}")
        return np.frombuffer(self.archive.read(f"{self.prefix}data/{key}"), dtype=dtype)


def _rebuild_tensor(storage: np.ndarray, offset: int, size: tuple[int, ...],
                    stride: tuple[int, ...], *_: Any) -> np.ndarray:
    """A tensor of ``storage`` as torch rebuilds it (its offset, shape and strides, in
    elements), copied out as a native-order array."""
    view = np.lib.stride_tricks.as_strided(storage[offset:], shape=size,
                                           strides=[s * storage.itemsize for s in stride])
    return np.array(view, dtype=storage.dtype.newbyteorder("="))


def state_dict(pth: bytes) -> dict[str, np.ndarray]:
    """The state dict in torch's zip ``pth`` (the bytes of a ``torch.save``) as NumPy
    arrays; ``ValueError`` for a file of another layout."""
    try:
        with zipfile.ZipFile(io.BytesIO(pth)) as archive:
            pickled = next(n for n in archive.namelist() if n.endswith("/data.pkl"))
            prefix = pickled[:-len("data.pkl")]
            order = archive.read(prefix + "byteorder").decode() if (
                prefix + "byteorder" in archive.namelist()) else "little"
            if order != "little":
                raise ValueError(f"weights stored {order}-endian")
            return dict(_StateDictUnpickler(archive.read(pickled), archive, prefix).load())
    except (zipfile.BadZipFile, StopIteration, pickle.UnpicklingError, ValueError, KeyError,
            TypeError) as error:
        raise ValueError(f"not torch's state dict of a policy ({error})") from None


def actor_of(weights: dict[str, np.ndarray], policy_kwargs: dict[str, Any]) -> ActorWeights:
    """The actor of an ``MlpPolicy`` state dict ``weights`` trained with
    ``policy_kwargs`` (sb3's; only ``net_arch`` may be set: the activation is then tanh and
    the observation read flat); ``ValueError`` otherwise."""
    others = sorted(set(policy_kwargs) - {"net_arch"})
    if others:
        raise ValueError(f"an actor of policy_kwargs {others} is not sb3's default MLP of "
                         "tanh layers on the flat observation")
    hidden = sorted(int(k.split(".")[2]) for k in weights
                    if k.startswith("mlp_extractor.policy_net.") and k.endswith(".weight"))
    names = [f"mlp_extractor.policy_net.{i}" for i in hidden] + ["action_net"]
    try:
        layers = [(weights[n + ".weight"], weights[n + ".bias"]) for n in names]
    except KeyError as missing:
        raise ValueError(f"the state dict has no {missing}: not an actor-critic MLP") from None
    for (w, _), (w_next, _) in itertools.pairwise(layers):
        if w.shape[0] != w_next.shape[1]:
            raise ValueError(f"the actor's layers do not chain: {w.shape} then {w_next.shape}")
    return ActorWeights(tuple(np.ascontiguousarray(w, dtype=np.float32) for w, _ in layers),
                        tuple(np.ascontiguousarray(b, dtype=np.float32) for _, b in layers))


@lru_cache(maxsize=4)
def _read(path: str, modified_ns: int) -> ActorWeights:
    with zipfile.ZipFile(path) as archive:
        data = json.loads(archive.read("data"))
        pth = archive.read("policy.pth")
    module = data.get("policy_class", {}).get("__module__")
    if module not in ACTOR_CRITIC_MODULES:
        raise ValueError(f"its policy class is of {module}, not MaskablePPO's actor-critic")
    return actor_of(state_dict(pth), data.get("policy_kwargs") or {})


def read_actor(path: str | Path) -> ActorWeights:
    """The actor of the stable-baselines3 MaskablePPO file ``path`` (read once per file
    version); ``ValueError`` saying why a file cannot be read so."""
    path = Path(path)
    try:
        return _read(str(path.resolve()), path.stat().st_mtime_ns)
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, ValueError) as error:
        raise ValueError(f"policy file '{path}': its network cannot be read in NumPy: "
                         f"{error}") from None
