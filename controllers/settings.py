"""Typed, validated settings for the controller components."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

__all__ = ["AUTHORITY_MAX_LEVELS", "SynthesisSettings", "ControllerSettings", "SettingsError", "default_cache_dir"]

SOLVERS = ("exact", "daqp", "proxsuite")
STRUCTURES = ("auto", "full")
MODES = ("paper", "authority")


class SettingsError(ValueError):
    """Invalid settings value; the message names the field and what is valid."""


def default_cache_dir() -> Path:
    """Where synthesised sets are cached: ``$MUVSIM_CACHE_DIR`` or ``~/.cache/muvsim``."""
    env = os.environ.get("MUVSIM_CACHE_DIR")
    return Path(env) if env else Path.home() / ".cache" / "muvsim"


#: ``SynthesisSettings.max_levels`` of the movement-authority families the co-simulation builds
#: (at least this): a vType class braking at 1.04 m/s^2 from 24.98 m/s (the braking budget of
#: ``controllers.classes.BRAKING_BUDGET_M``) needs 224 levels (0.7 s on one core), more than the
#: default 200.  The paper's families stop at condition (8) long before either bound.
AUTHORITY_MAX_LEVELS = 400


@dataclass(frozen=True)
class SynthesisSettings:
    """Offline synthesis (Off-1, Off-2) settings.

    Parameters
    ----------
    q_weight, r_weight : float
        LQR weights ``Q = q I``, ``R = r I`` of the terminal gain.
    epsilon : float
        Accuracy (m, m/s, ... in the infinity norm) of the Rakovic outer
        approximation of the minimal RPI set used as ``T^0``.
    max_levels : int
        Bound on N; reaching it before condition (8) holds is an error.
    terminal_method : {"auto", "zonotope", "maximal"}
        How ``T^0`` is represented.  ``zonotope``: the Rakovic approximation
        ``F(alpha, s)`` itself (2-D factors only: a zonotope with g generators
        has 2g edges in 2-D but O(g^2) facets in 3-D).  ``maximal``: the maximal
        RPI set inside the epsilon-enlarged bounding box of ``F(alpha, s)``;
        it contains the minimal RPI set and has few facets in any dimension.
        ``auto``: zonotope for 2-D factors, maximal otherwise.
    extra_levels : int
        One-step sets computed beyond the first level where condition (8)
        holds.  Larger domains let a vehicle aim at a waypoint from further
        away and so drive faster between waypoints (its tube is larger while
        it does); 0 is the paper's minimal family.
    structure : {"auto", "full"}
        ``auto`` works on decoupled factors (products of low-dimensional sets);
        ``full`` uses the general n-D path on the whole state.
    authority_decel : float or None
        Movement-authority mode (design.md §7) when set: a comfortable deceleration
        ``a_c`` (m/s^2, ``0 < a_c <`` the along-road input bound).  The family then
        continues past the first level meeting condition (8) up to ``N_L``, the first
        level whose along-road factor contains the state ``(-s_MA, v̄)`` with
        ``s_MA = v̄^2 / (2 a_c) + 2 delta``; every factor gets the same ``N_L`` levels.
        ``None`` (default): the paper's family, unchanged (and its cache key).
    cache : bool
        Read and write the on-disk cache.
    cache_dir : Path or None
        Cache location (default :func:`default_cache_dir`).
    """

    q_weight: float = 1.0
    r_weight: float = 1.0
    epsilon: float = 0.05
    max_levels: int = 200
    terminal_method: Literal["auto", "zonotope", "maximal"] = "auto"
    extra_levels: int = 0
    structure: Literal["auto", "full"] = "auto"
    authority_decel: float | None = None
    cache: bool = True
    cache_dir: Path | None = None

    def __post_init__(self) -> None:
        for name in ("q_weight", "r_weight", "epsilon"):
            v = getattr(self, name)
            if not isinstance(v, (int, float)) or not v > 0:
                raise SettingsError(f"SynthesisSettings.{name}: must be a number > 0, got {v!r}")
        if not isinstance(self.max_levels, int) or self.max_levels < 1:
            raise SettingsError(f"SynthesisSettings.max_levels: must be an integer >= 1, got {self.max_levels!r}")
        if self.terminal_method not in ("auto", "zonotope", "maximal"):
            raise SettingsError("SynthesisSettings.terminal_method: must be 'auto', 'zonotope' or "
                                f"'maximal', got {self.terminal_method!r}")
        if not isinstance(self.extra_levels, int) or self.extra_levels < 0:
            raise SettingsError(f"SynthesisSettings.extra_levels: must be an integer >= 0, got {self.extra_levels!r}")
        if self.structure not in STRUCTURES:
            raise SettingsError(f"SynthesisSettings.structure: must be one of {STRUCTURES}, got {self.structure!r}")
        a = self.authority_decel
        if a is not None and (isinstance(a, bool) or not isinstance(a, (int, float)) or not a > 0):
            raise SettingsError("SynthesisSettings.authority_decel: must be None (paper family) or a "
                                f"deceleration > 0 m/s^2, got {a!r}")

    def key(self) -> str:
        """The part of the cache key that depends on the settings."""
        return f"q{self.q_weight:g}-r{self.r_weight:g}-e{self.epsilon:g}-L{self.max_levels}-" \
               f"T{self.terminal_method}-{self.structure}-x{self.extra_levels}" + \
            ("" if self.authority_decel is None else f"-MA{self.authority_decel:g}")


@dataclass(frozen=True)
class ControllerSettings:
    """Online ST-MPC settings.

    Parameters
    ----------
    solver : {"exact", "daqp", "proxsuite"}
        QP solver of eq. (6).  ``exact`` solves the QP in closed form per
        decoupled factor with one input (the QP separates exactly there) and
        falls back to ``daqp`` for factors with several inputs.
    switching : {"terminal", "early"}
        ``terminal`` asks to switch waypoint only from ``T^0`` (the paper);
        ``early`` asks whenever the state lies in the next waypoint's domain.
    mode : {"paper", "authority"}
        ``paper``: the cost of eq. (6) (pull to the waypoint's equilibrium).
        ``authority`` (needs a movement-authority family, see
        :class:`SynthesisSettings`): the along-road cost tracks
        ``v_des = min(v̄, cap, sqrt(2 a_c (s(c) - s(x) - s0)))`` instead; the tube
        constraint of eq. (6) is unchanged, so is every guarantee.
    standoff : float
        ``s0`` (m, >= 0) of ``v_des``: how far short of its waypoint the cost aims to stop.
    """

    solver: Literal["exact", "daqp", "proxsuite"] = "exact"
    switching: Literal["terminal", "early"] = "early"
    mode: Literal["paper", "authority"] = "paper"
    standoff: float = 0.0

    def __post_init__(self) -> None:
        if self.solver not in SOLVERS:
            raise SettingsError(f"ControllerSettings.solver: must be one of {SOLVERS}, got {self.solver!r}")
        if self.switching not in ("terminal", "early"):
            raise SettingsError(
                f"ControllerSettings.switching: must be 'terminal' or 'early', got {self.switching!r}")
        if self.mode not in MODES:
            raise SettingsError(f"ControllerSettings.mode: must be one of {MODES}, got {self.mode!r}")
        if not isinstance(self.standoff, (int, float)) or not self.standoff >= 0:
            raise SettingsError(f"ControllerSettings.standoff: must be a distance >= 0 m, got {self.standoff!r}")
