"""Built-in vehicle classes: a model, a footprint and a SUMO vClass.

* ``paper-a`` .. ``paper-d``: the four classes of the paper's section IV
  (double integrator, ``Ts = 0.1 s``, ``u_max = 4``), footprint of a car.
* ``car``, ``bus``, ``truck``: urban classes for SUMO roads (13.89 m/s =
  50 km/h), footprints equal to SUMO's default vTypes of the same vClass
  (passenger 5 x 1.8 m, bus 12 x 2.5 m, truck 7.1 x 2.4 m).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from controllers.models import VehicleModel, double_integrator, drag_integrator

__all__ = ["VehicleClass", "VTypeParams", "builtin_classes", "get_class", "vtype_class", "ClassError",
           "CITY_TURN_MAX_DEG", "CITY_V_MAX", "VTYPE_V_MAX", "CITY_U_MAX", "BRAKING_BUDGET_M", "vtype_speed_cap"]

#: Largest heading change between successive route segments the urban classes accept.
CITY_TURN_MAX_DEG = 45.0
#: Speed bound along the road of the built-in urban classes car, bus and truck (m/s, 50 km/h).
CITY_V_MAX = 13.89
#: Largest speed bound along the road of a class built from a vType (m/s, 130 km/h): its maxSpeed
#: capped by this; the lanes' speed limits bind below it (``--speed-limits``).  At 13.89 m/s
#: (the urban classes' bound) muvsim drove SUMO's motorway demos (``ramp``: 33.3 m/s lanes,
#: ``A10KW``) at 50 km/h.  Synthesis of a car's movement-authority family to 36.11 m/s: 0.7 s
#: (one core, measured against 0.5 s at 13.89 m/s).
VTYPE_V_MAX = 36.11
#: Longest movement-authority braking distance of a class built from a vType (m): its speed bound
#: is at most ``sqrt(2 a_c B)``.  A truck vType (accel 1.3 m/s^2, so ``a_c`` = 1.04) at 36.11 m/s
#: needs 633 m, more than the synthesis's 200 levels of δ = 3 m reach, and the run failed
#: (SUMO's ``A10KW``); with 300 m it drives at most 24.98 m/s (90 km/h), a car vType (``a_c`` =
#: 2.08) at most 35.33 m/s.
BRAKING_BUDGET_M = 300.0
#: Largest acceleration bound along the road of a class built from a vType (m/s^2).
CITY_U_MAX = 3.0

#: Movement-authority deceleration ``a_c`` of the car (m/s^2): 5/6 of its 3 m/s^2 input bound,
#: the figure design.md §7 was prototyped with (s_MA = 44.6 m at 13.89 m/s).
CAR_COMFORT_DECEL = 2.5
#: ``a_c`` of bus and truck (m/s^2): 0.8 of their 1.5 m/s^2 bound, within the 1-1.5 m/s^2
#: usually taken as comfortable service braking with standing passengers / loose cargo; the
#: rest (0.3 m/s^2) is the margin the tube needs against the disturbance.
HEAVY_COMFORT_DECEL = 1.2


class ClassError(KeyError):
    """Unknown vehicle class."""

    def __str__(self) -> str:  # KeyError quotes its message otherwise
        return str(self.args[0])


@dataclass(frozen=True)
class VehicleClass:
    """A vehicle class: dynamics and constraints plus a rectangular footprint.

    Parameters
    ----------
    name : str
    model : VehicleModel
    length, width : float
        Footprint (m), centred on the state's position.
    vclass : str
        SUMO vClass this class stands for.
    comfort_decel : float or None
        ``a_c`` (m/s^2) of the movement-authority mode (design.md §7), below the
        along-road input bound; None for classes that only run the paper's mode.
    """

    name: str
    model: VehicleModel
    length: float
    width: float
    vclass: str
    comfort_decel: float | None = None

    def __post_init__(self) -> None:
        if not (self.length > 0 and self.width > 0):
            raise ValueError(f"class {self.name!r}: length and width must be > 0 m, "
                             f"got {self.length} x {self.width}")
        if self.comfort_decel is not None and not 0 < self.comfort_decel < float(self.model.u_bounds[1][0]):
            raise ValueError(f"class {self.name!r}: comfort_decel must lie in (0, {self.model.u_bounds[1][0]:g}) "
                             f"m/s^2 (the along-road input bound), got {self.comfort_decel}")

    @property
    def v_max(self) -> float:
        """Per-axis speed bound (m/s)."""
        return float(self.model.z_bounds[1][0])


@dataclass(frozen=True)
class VTypeParams:
    """The parameters of a SUMO vType a vehicle class is built from (as SUMO has them,
    its defaults per vClass filled in: read back with ``libsumo.vehicletype.get*``).

    Parameters
    ----------
    vclass : str
        SUMO vClass.
    length, width : float
        Footprint (m), > 0.
    accel, decel : float
        Acceleration and deceleration ability (m/s^2), > 0.
    max_speed : float
        Maximum speed (m/s), > 0.
    """

    vclass: str
    length: float
    width: float
    accel: float
    decel: float
    max_speed: float

    def __post_init__(self) -> None:
        for k in ("length", "width", "accel", "decel", "max_speed"):
            v = getattr(self, k)
            if not (isinstance(v, (int, float)) and v > 0 and v < float("inf")):
                raise ValueError(f"vType parameter {k}: must be a finite number > 0, got {v!r}")

    @property
    def name(self) -> str:
        """The class name: vClass and every parameter (one class per distinct parameter set)."""
        return (f"{self.vclass}-{self.length:g}x{self.width:g}-a{self.accel:g}-d{self.decel:g}"
                f"-v{self.max_speed:g}")


def vtype_speed_cap(max_lane_speed: float) -> float:
    """The speed bound of the classes built from a network's vTypes (m/s): its fastest lane's
    limit, at least :data:`CITY_V_MAX` (a city network keeps the urban classes' bound and sets)
    and at most :data:`VTYPE_V_MAX`.  Measured on SUMO's ``grid6`` (lanes 13.9 m/s, 180 s): with
    every vType at 36.11 m/s, 18 arrivals against 26 -- larger sets for speeds no lane allows."""
    return float(min(max(float(max_lane_speed), CITY_V_MAX), VTYPE_V_MAX))


def vtype_class(p: VTypeParams, v_cap: float = VTYPE_V_MAX) -> VehicleClass:
    """A road-frame urban class built from a vType's parameters.

    Footprint: exactly the vType's ``length x width`` (what SUMO moves and judges).
    Dynamics: a double integrator in the road frame like the built-in ``car``, with the
    speed bound along the road ``min(max_speed, v_cap)`` (``v_cap`` at most :data:`VTYPE_V_MAX`:
    the network's fastest lane, :func:`vtype_speed_cap`) and the input bound
    ``min(accel, decel, CITY_U_MAX)`` (the model's input box is symmetric, so the smaller
    of the two abilities bounds both); across the road as ``car``.  Its sets are
    synthesised on first use and cached on disk by the model (:mod:`controllers.synthesis`).
    ``comfort_decel`` (movement-authority mode): ``min(0.8 u, CAR_COMFORT_DECEL)``; the speed
    bound is also at most ``sqrt(2 comfort_decel BRAKING_BUDGET_M)``.
    """
    if not (np.isfinite(v_cap) and v_cap > 0):
        raise ValueError(f"vtype_class: v_cap must be a speed > 0 m/s, got {v_cap!r}")
    u = round(min(p.accel, p.decel, CITY_U_MAX), 4)
    comfort = min(CAR_COMFORT_DECEL, round(0.8 * u, 4))
    # and no faster than it stops within the braking budget at its comfortable deceleration
    v_brake = np.floor(np.sqrt(2.0 * comfort * BRAKING_BUDGET_M) * 1e4) / 1e4
    v = round(min(p.max_speed, v_cap, VTYPE_V_MAX, v_brake), 4)
    model = double_integrator(v_max=(v, 0.2), u_max=(u, 0.5), d_max=0.005, name=p.name, frame="road",
                              turn_max_deg=CITY_TURN_MAX_DEG, delta=3.0)
    # movement-authority mode: a comfortable deceleration of 0.8 of the input bound (as the built-in
    # truck and bus: 1.2 of 1.5 m/s^2), at most the car's (comfort, above)
    return VehicleClass(p.name, model, length=float(p.length), width=float(p.width), vclass=p.vclass,
                        comfort_decel=comfort)


def builtin_classes() -> dict[str, VehicleClass]:
    """All built-in classes, freshly built (models are immutable values)."""
    paper = {  # name: (v_max, d_max, delta)  -- paper section IV
        "paper-a": (20.0, 0.06, 4.02),
        "paper-b": (25.0, 0.085, 5.62),
        "paper-c": (8.0, 0.07, 3.22),
        "paper-d": (18.0, 0.065, 3.91),
    }
    out = {
        name: VehicleClass(name, double_integrator(v_max=v, u_max=4.0, d_max=d, delta=dl, name=name),
                           length=5.0, width=1.8, vclass="passenger")
        for name, (v, d, dl) in paper.items()
    }
    # Urban classes work in the road frame (x along the segment, y across): fast along the
    # road, slow and tightly disturbed across it, so their tubes stay inside ~ a lane.
    road = dict(frame="road", turn_max_deg=CITY_TURN_MAX_DEG, delta=3.0)
    out["car"] = VehicleClass(
        "car", double_integrator(v_max=(13.89, 0.2), u_max=(3.0, 0.5), d_max=0.005, name="car", **road),
        length=5.0, width=1.8, vclass="passenger", comfort_decel=CAR_COMFORT_DECEL)
    out["bus"] = VehicleClass(
        "bus", drag_integrator(v_max=(13.89, 0.2), u_max=(1.5, 0.5), d_max=0.005, tau=10.0, name="bus",
                               **road),
        length=12.0, width=2.5, vclass="bus", comfort_decel=HEAVY_COMFORT_DECEL)
    out["truck"] = VehicleClass(
        "truck", double_integrator(v_max=(13.89, 0.2), u_max=(1.5, 0.5), d_max=0.005, name="truck",
                                   **road),
        length=7.1, width=2.4, vclass="truck", comfort_decel=HEAVY_COMFORT_DECEL)
    return out


def get_class(name: str) -> VehicleClass:
    """A built-in class by name; the error lists the valid names."""
    classes = builtin_classes()
    if name not in classes:
        raise ClassError(f"unknown vehicle class {name!r}; valid classes: {', '.join(classes)}")
    return classes[name]
