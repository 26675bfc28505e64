import numpy as np
import pytest

from controllers.models import ModelError, VehicleModel, decoupled_blocks, double_integrator, \
    drag_integrator, jerk_integrator


def _di(**over):
    kw = dict(v_max=10.0, u_max=4.0, d_max=0.05, delta=3.0)
    kw.update(over)
    return double_integrator(**kw)


def test_models_satisfy_assumption_2_and_decouple_per_axis():
    for m in (_di(), drag_integrator(v_max=10, u_max=3, d_max=0.02, delta=3),
              jerk_integrator(v_max=10, a_max=3, j_max=10, d_max=0.01, delta=2)):
        assert np.allclose(m.A[:2, :2], np.eye(2)) and np.allclose(m.A[2:, :2], 0)
        x_eq = m.equilibrium(np.array([3.0, -2.0]))
        assert np.allclose(m.A @ x_eq, x_eq)  # equilibrium for any position
        blocks = decoupled_blocks(m)
        assert len(blocks) == 2 and all(len(u) == 1 for _, u in blocks)


def test_unreachable_pair_is_rejected():
    m = _di()
    B = m.B.copy()
    B[:, 1] = 0.0  # y axis no longer driven
    with pytest.raises(ModelError, match="not reachable"):
        VehicleModel(name="x", A=m.A, B=B, z_bounds=m.z_bounds, u_bounds=m.u_bounds,
                     d_bounds=m.d_bounds, delta=3.0, Ts=0.1)


@pytest.mark.parametrize("field, kwargs, message", [
    ("z_bounds", dict(z_bounds=([1.0, -1.0], [-1.0, 1.0])), "z_bounds: empty box"),
    ("u_bounds", dict(u_bounds=([0.5, 0.5], [1.0, 1.0])), "u_bounds: the u_bounds must contain 0"),
    ("d_bounds", dict(d_bounds=([0.01] * 4, [0.02] * 4)), "d_bounds: the disturbance set D must contain 0"),
    ("d_bounds", dict(d_bounds=([-1.0] * 3, [1.0] * 3)), "d_bounds: expected 4"),
    ("z_bounds", dict(z_bounds=([-np.inf, -1.0], [np.inf, 1.0])), "z_bounds: bounds must be finite"),
    ("delta", dict(delta=0.0), "delta: the waypoint spacing must be > 0"),
    ("delta", dict(delta=-1.0), "delta"),
    ("Ts", dict(Ts=0.0), "Ts: the sampling time must be > 0"),
])
def test_invalid_fields_name_the_field(field, kwargs, message):
    m = _di()
    base = dict(name="x", A=m.A, B=m.B, z_bounds=m.z_bounds, u_bounds=m.u_bounds,
                d_bounds=m.d_bounds, delta=3.0, Ts=0.1)
    base.update(kwargs)
    with pytest.raises(ModelError, match=message.replace("(", r"\(")) as exc:
        VehicleModel(**base)
    assert field in str(exc.value)


def test_assumption_2_violation_is_named():
    m = _di()
    A = m.A.copy()
    A[0, 0] = 0.9
    with pytest.raises(ModelError, match="Assumption 2"):
        VehicleModel(name="x", A=A, B=m.B, z_bounds=m.z_bounds, u_bounds=m.u_bounds,
                     d_bounds=m.d_bounds, delta=3.0, Ts=0.1)


def test_models_are_frozen_values():
    m = _di()
    with pytest.raises(Exception):
        m.delta = 2.0
    with pytest.raises(ValueError):
        m.A[0, 0] = 3.0
    assert m.key() == _di().key() and m.key() != _di(delta=3.5).key()
