"""Frozen model parameters and controller gains (numpy only; every number a configurable default).

The paper fixes the master link lengths, the gains (39) and the trajectory (40); every slave number is
our proposal (docs/models.md).  Task space x = [X, Z] (m), Z up, gravity along -Z; rad, 1/m, N, N m.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields

import numpy as np

GRAVITY = 9.81  # m/s^2, standard gravity (magnitude)
Q2_NAMES = ("d1", "d2", "d3", "k1", "k2", "k3")  # the slave's q2: section lengths (m), curvatures (1/m)
SUBTASKS = ("manipulability", "limits")  # the null-space sub-task kinds (29)-(33) of `controllers.subtasks`


class ParameterError(ValueError):
    """Parameters the schema's per-field ranges cannot check (one line naming the field)."""


def _as_tuples(obj, variable: tuple[str, ...] = ()) -> None:
    """Store the number-tuple fields of a parameter dataclass as tuples of floats (lists, arrays accepted);
    ParameterError if one not in `variable` has another length than its default (the packed layout)."""
    for f in fields(obj):
        v = getattr(obj, f.name)
        if not (isinstance(f.default, tuple) and all(isinstance(x, float) for x in f.default)):
            continue
        if not (type(v) is tuple and all(type(x) is float for x in v)):
            v = tuple(float(x) for x in np.ravel(v))
            object.__setattr__(obj, f.name, v)
        if f.name not in variable and len(v) != len(f.default):
            raise ParameterError(f"{type(obj).__name__}.{f.name} = {v!r}: must have {len(f.default)} entries")


def _packed(name: str, default: tuple):
    """A dataclass field that enters the packed parameter vector of the kernels under `name`."""
    return field(default=default, metadata={"pack": name, "size": len(default)})


def _pack_layout(cls) -> tuple[tuple[str, ...], dict[str, int], int]:
    """(field names, pack name -> offset, size) of the `_packed` fields, in declaration order."""
    names, offsets, off = [], {}, 0
    for f in fields(cls):
        if "pack" in f.metadata:
            names.append(f.name)
            offsets[f.metadata["pack"]] = off
            off += f.metadata["size"]
    return tuple(names), offsets, off


@dataclass(frozen=True)
class MasterParams:
    """Planar 2-link revolute master (paper Sec. II-C, VI); uniform links (`controllers.master`)."""

    lengths: tuple[float, float] = (0.6, 0.6)  # m, paper Sec. VI
    masses: tuple[float, float] = (1.0, 1.0)  # kg, our proposal
    damping: tuple[float, float] = (0.0, 0.0)  # N m s/rad, viscous joint friction (optional)
    gravity: float = GRAVITY  # m/s^2 along -Z

    def __post_init__(self) -> None:
        _as_tuples(self)

    @property
    def inertias(self) -> tuple[float, float]:
        """Link inertia about its centre of mass around the joint axis, kg m^2 (uniform rod)."""
        return tuple(m * l * l / 12.0 for m, l in zip(self.masses, self.lengths, strict=True))


@dataclass(frozen=True)
class SlaveParams:
    """Planar 3-section constant-curvature Octarm, q2 = [d1, d2, d3 (m), k1, k2, k3 (1/m)]
    (`controllers.slave`).  `_packed` fields enter `packed()` (layout SLAVE_PACK) in this order."""

    rest_lengths: tuple[float, float, float] = _packed("L0", (0.30, 0.30, 0.30))  # L0, m
    masses: tuple[float, float, float] = _packed("m", (1.0, 0.7, 0.4))  # kg, base to tip
    bending_stiffness: tuple[float, float, float] = _packed("Kb", (8.0, 3.0, 1.0))  # Kb, N m^2
    extension_stiffness: tuple[float, float, float] = _packed("Ke", (1000.0, 700.0, 400.0))  # Ke, N/m
    # viscous damping on [d-rates (N s/m), k-rates (N m^2 s)], optional
    extension_damping: tuple[float, float, float] = _packed("cd", (0.0, 0.0, 0.0))
    bending_damping: tuple[float, float, float] = _packed("ck", (0.0, 0.0, 0.0))
    # rotational inertia of the cross-section slices per unit material coordinate, kg m^2 (optional)
    slice_inertia: tuple[float, float, float] = _packed("Is", (0.0, 0.0, 0.0))
    gravity: tuple[float, float] = _packed("g", (0.0, -GRAVITY))  # gravity vector in (X, Z), m/s^2
    max_extension: float = 1.5  # section length range [L0, max_extension * L0]
    max_bend: float = float(np.pi / 2)  # |k_i d_i| <= max_bend, rad
    n_quad: int = 8  # Gauss-Legendre points per section for the energy integrals

    def __post_init__(self) -> None:
        _as_tuples(self)

    @property
    def length_range(self) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi) (3,) each, m: the section lengths' range [L0, max_extension L0]."""
        L0 = np.asarray(self.rest_lengths)
        return L0.copy(), self.max_extension * L0

    def packed(self) -> np.ndarray:
        """float64 (SLAVE_PACK_SIZE,): entry SLAVE_PACK[name] + i = component i of that field."""
        return np.concatenate([getattr(self, f) for f in _PACK_FIELDS]).astype(np.float64)


_PACK_FIELDS, SLAVE_PACK, SLAVE_PACK_SIZE = _pack_layout(SlaveParams)


@dataclass(frozen=True)
class Gains:
    """Controller gains, paper eq. (39)."""

    k1: float = 3.0
    k2: float = 10.0
    k3: float = 10.0
    k4: float = 15.0
    ky: float = 1.0
    ks: float = 1.0
    kn: float = 100.0

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, float(getattr(self, f.name)))

    def packed(self) -> np.ndarray:
        return np.array([self.k1, self.k2, self.k3, self.k4, self.ky, self.ks, self.kn])


@dataclass(frozen=True)
class SubtaskSpec:
    """Null-space sub-tasks (29)-(33): beta = sum_j weights_j beta_j(q2) over `kinds` (subset of
    {"manipulability", "limits"}); `limit_power` p of the limits term (`controllers.subtasks`)."""

    kinds: tuple[str, ...] = ("manipulability", "limits")
    weights: tuple[float, ...] = (1.0, 0.05)
    limit_power: int = 4

    def __post_init__(self) -> None:
        object.__setattr__(self, "kinds", tuple(self.kinds))
        _as_tuples(self, variable=("weights",))
        if len(set(self.kinds)) != len(self.kinds) or not set(self.kinds) <= set(SUBTASKS):
            raise ParameterError(f"subtask.kinds = {self.kinds!r}: must be distinct kinds of {SUBTASKS}")
        if len(self.weights) != len(self.kinds):
            raise ParameterError(
                f"subtask.weights = {self.weights!r}: need one weight per kind ({len(self.kinds)})")


__all__ = ["GRAVITY", "SLAVE_PACK", "SUBTASKS", "SLAVE_PACK_SIZE", "Gains", "MasterParams", "ParameterError",
           "SlaveParams", "SubtaskSpec", "field"]
