"""Nominal quadrotor model (paper eqs (6)-(9)) and rotor mixer (51), batched over vehicles.

Frames: world ENU (z up, gravity ``-GRAVITY_MPS2 e3``); body FLU, thrust ``T >= 0`` along body
+z; ``rotation`` maps body to world; ``omega_radps`` and ``torque_nm`` are body-frame. Arrays are
float64, C-contiguous, with the vehicle index first: positions/velocities/rates ``(n, 3)``,
rotations ``(n, 3, 3)``, scalars per vehicle ``(n,)``; inertias are the diagonal ``(n, 3)``.

The hot functions are ``numba.njit(cache=True)`` so that other njit code (a simulation loop) can
call them; they are plain Python under ``NUMBA_DISABLE_JIT=1``. Inside them every vehicle is
handled with scalar math on 3-tuples (kept in registers), so ``rk4_step`` does not allocate.
Pure: no clock, no I/O; depends on numpy and numba only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
Vec3 = tuple[float, float, float]
# One vehicle's state inside the kernels: (p, v, row 0, row 1, row 2 of R, omega).
State = tuple[Vec3, Vec3, Vec3, Vec3, Vec3, Vec3]

GRAVITY_MPS2 = 9.81
# Re-orthonormalisation: stop when max |R R^T - I| is below this (a few ulps), at most 3 passes.
_ORTHO_TOL = 1e-14
_ORTHO_MAX_PASSES = 3


@dataclass(frozen=True, slots=True)
class InertialParameters:
    """One airframe of the paper's Table I: mass and principal inertias about body FLU axes."""

    name: str
    mass_kg: float
    inertia_kgm2: tuple[float, float, float]


TABLE_I: tuple[InertialParameters, ...] = (
    InertialParameters("UAV1", 0.85, (4.856e-2, 4.856e-2, 8.801e-2)),
    InertialParameters("UAV2", 1.2, (1.522e-1, 1.522e-1, 3.0e-1)),
    InertialParameters("UAV3", 0.35, (2.56e-2, 2.56e-2, 5.2e-2)),
    InertialParameters("UAV4", 3.4, (3.54e-1, 3.54e-1, 6.54e-1)),
)


def table_i_arrays() -> tuple[FloatArray, FloatArray]:
    """Table I as arrays: ``(mass_kg (4,), inertia_kgm2 (4, 3))``."""
    mass_kg = np.array([a.mass_kg for a in TABLE_I], dtype=np.float64)
    inertia_kgm2 = np.array([a.inertia_kgm2 for a in TABLE_I], dtype=np.float64)
    return mass_kg, inertia_kgm2


# --- 3-tuple helpers (no allocation under JIT) -------------------------------------------------


@njit(cache=True)
def _row(a: FloatArray, i: int) -> Vec3:
    return (a[i, 0], a[i, 1], a[i, 2])


@njit(cache=True)
def _put(a: FloatArray, i: int, t: Vec3) -> None:
    a[i, 0] = t[0]
    a[i, 1] = t[1]
    a[i, 2] = t[2]


@njit(cache=True)
def _load(p: FloatArray, v: FloatArray, r: FloatArray, w: FloatArray, i: int) -> State:
    return (_row(p, i), _row(v, i), _row(r[i], 0), _row(r[i], 1), _row(r[i], 2), _row(w, i))


@njit(cache=True)
def _store(p: FloatArray, v: FloatArray, r: FloatArray, w: FloatArray, i: int, x: State) -> None:
    _put(p, i, x[0])
    _put(v, i, x[1])
    _put(r[i], 0, x[2])
    _put(r[i], 1, x[3])
    _put(r[i], 2, x[4])
    _put(w, i, x[5])


@njit(cache=True)
def _cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True)
def _dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _lin3(ca: float, a: Vec3, cb: float, b: Vec3, cc: float, c: Vec3) -> Vec3:
    """ca a + cb b + cc c for 3-tuples."""
    return (
        ca * a[0] + cb * b[0] + cc * c[0],
        ca * a[1] + cb * b[1] + cc * c[1],
        ca * a[2] + cb * b[2] + cc * c[2],
    )


@njit(cache=True)
def _axpy(x: Vec3, h: float, k: Vec3) -> Vec3:
    return (x[0] + h * k[0], x[1] + h * k[1], x[2] + h * k[2])


@njit(cache=True)
def _advance(x: State, k: State, h: float) -> State:
    """x + h k for a whole State."""
    return (
        _axpy(x[0], h, k[0]),
        _axpy(x[1], h, k[1]),
        _axpy(x[2], h, k[2]),
        _axpy(x[3], h, k[3]),
        _axpy(x[4], h, k[4]),
        _axpy(x[5], h, k[5]),
    )


@njit(cache=True)
def _rates(x: State, accel_mps2: float, tau: Vec3, j: Vec3) -> State:
    """Eqs (6)-(9) for one vehicle; x = (p, v, rows of R, omega), accel = T/m.

    Row i of R hat(omega) is (row i of R) x omega.
    """
    v, r0, r1, r2, w = x[1], x[2], x[3], x[4], x[5]
    v_dot = (accel_mps2 * r0[2], accel_mps2 * r1[2], accel_mps2 * r2[2] - GRAVITY_MPS2)
    w_dot = (
        ((j[1] - j[2]) * w[1] * w[2] + tau[0]) / j[0],
        ((j[2] - j[0]) * w[2] * w[0] + tau[1]) / j[1],
        ((j[0] - j[1]) * w[0] * w[1] + tau[2]) / j[2],
    )
    return (v, v_dot, _cross(r0, w), _cross(r1, w), _cross(r2, w), w_dot)


@njit(cache=True)
def _orthonormalise(r0: Vec3, r1: Vec3, r2: Vec3) -> tuple[Vec3, Vec3, Vec3]:
    """Newton-Schulz polar step R <- R (3I - R^T R)/2 = (I - E/2) R, E = R R^T - I, on rows.

    Equals the SVD polar factor (the nearest rotation) up to O(|E|^2); converges for singular
    values in (0, sqrt 3) and keeps det = +1 near SO(3).
    """
    for _ in range(_ORTHO_MAX_PASSES):
        e00 = _dot(r0, r0) - 1.0
        e11 = _dot(r1, r1) - 1.0
        e22 = _dot(r2, r2) - 1.0
        e01 = _dot(r0, r1)
        e02 = _dot(r0, r2)
        e12 = _dot(r1, r2)
        err = max(abs(e00), abs(e11), abs(e22), abs(e01), abs(e02), abs(e12))
        if err <= _ORTHO_TOL:
            break
        r0, r1, r2 = (
            _lin3(1.0 - 0.5 * e00, r0, -0.5 * e01, r1, -0.5 * e02, r2),
            _lin3(-0.5 * e01, r0, 1.0 - 0.5 * e11, r1, -0.5 * e12, r2),
            _lin3(-0.5 * e02, r0, -0.5 * e12, r1, 1.0 - 0.5 * e22, r2),
        )
    return r0, r1, r2


@njit(cache=True)
def _check_state(
    position_m: FloatArray,
    velocity_mps: FloatArray,
    rotation: FloatArray,
    omega_radps: FloatArray,
    thrust_n: FloatArray,
    torque_nm: FloatArray,
    mass_kg: FloatArray,
    inertia_kgm2: FloatArray,
) -> int:
    n = position_m.shape[0]
    if (
        position_m.shape[1] != 3
        or velocity_mps.shape != position_m.shape
        or omega_radps.shape != position_m.shape
        or torque_nm.shape != position_m.shape
        or inertia_kgm2.shape != position_m.shape
        or rotation.shape != (n, 3, 3)
        or thrust_n.shape[0] != n
        or mass_kg.shape[0] != n
    ):
        raise ValueError("physics: expected shapes (n,3),(n,3),(n,3,3),(n,3),(n,),(n,3),(n,),(n,3)")
    return n


# --- public model --------------------------------------------------------------------------------


@njit(cache=True)
def hat(v: FloatArray) -> FloatArray:
    """Skew matrix of a 3-vector: hat(v) @ y == cross(v, y)."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@njit(cache=True)
def vee(m: FloatArray) -> FloatArray:
    """Inverse of hat for a skew 3x3 matrix (antisymmetric part used)."""
    return np.array([m[2, 1] - m[1, 2], m[0, 2] - m[2, 0], m[1, 0] - m[0, 1]]) * 0.5


@njit(cache=True)
def orthonormalise(rotation: FloatArray) -> None:
    """Project every R (n, 3, 3) onto SO(3) in place: the step rk4_step applies (its doc)."""
    for i in range(rotation.shape[0]):
        r = rotation[i]
        r0, r1, r2 = _orthonormalise(_row(r, 0), _row(r, 1), _row(r, 2))
        _put(r, 0, r0)
        _put(r, 1, r1)
        _put(r, 2, r2)


@njit(cache=True)
def derivatives(
    position_m: FloatArray,
    velocity_mps: FloatArray,
    rotation: FloatArray,
    omega_radps: FloatArray,
    thrust_n: FloatArray,
    torque_nm: FloatArray,
    mass_kg: FloatArray,
    inertia_kgm2: FloatArray,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Right-hand side of eqs (6)-(9): new arrays (p' (n,3), v' (n,3), R' (n,3,3), omega' (n,3))."""
    n = _check_state(
        position_m, velocity_mps, rotation, omega_radps, thrust_n, torque_nm, mass_kg, inertia_kgm2
    )
    p_dot = np.empty((n, 3))
    v_dot = np.empty((n, 3))
    r_dot = np.empty((n, 3, 3))
    w_dot = np.empty((n, 3))
    for i in range(n):
        x = _load(position_m, velocity_mps, rotation, omega_radps, i)
        k = _rates(x, thrust_n[i] / mass_kg[i], _row(torque_nm, i), _row(inertia_kgm2, i))
        _store(p_dot, v_dot, r_dot, w_dot, i, k)
    return p_dot, v_dot, r_dot, w_dot


@njit(cache=True)
def rk4_step(
    position_m: FloatArray,
    velocity_mps: FloatArray,
    rotation: FloatArray,
    omega_radps: FloatArray,
    thrust_n: FloatArray,
    torque_nm: FloatArray,
    mass_kg: FloatArray,
    inertia_kgm2: FloatArray,
    dt_s: float,
) -> None:
    """Advance every vehicle by dt_s IN PLACE: classic RK4 on (p, v, R as 9 numbers, omega),
    inputs held constant over the step, then R re-orthonormalised (Newton-Schulz polar step,
    repeated until max|R R^T - I| <= 1e-14, at most 3 passes; one pass at 1 ms steps).
    Allocation-free; raises ValueError on inconsistent shapes.
    """
    n = _check_state(
        position_m, velocity_mps, rotation, omega_radps, thrust_n, torque_nm, mass_kg, inertia_kgm2
    )
    half_s = 0.5 * dt_s
    for i in range(n):
        accel = thrust_n[i] / mass_kg[i]
        tau = _row(torque_nm, i)
        j = _row(inertia_kgm2, i)
        x = _load(position_m, velocity_mps, rotation, omega_radps, i)
        k1 = _rates(x, accel, tau, j)
        k2 = _rates(_advance(x, k1, half_s), accel, tau, j)
        k3 = _rates(_advance(x, k2, half_s), accel, tau, j)
        k4 = _rates(_advance(x, k3, dt_s), accel, tau, j)
        slope = _advance(_advance(_advance(k1, k2, 2.0), k3, 2.0), k4, 1.0)
        x = _advance(x, slope, dt_s / 6.0)
        r0, r1, r2 = _orthonormalise(x[2], x[3], x[4])
        _store(position_m, velocity_mps, rotation, omega_radps, i, (x[0], x[1], r0, r1, r2, x[5]))


@njit(cache=True)
def rk4_step_copy(
    position_m: FloatArray,
    velocity_mps: FloatArray,
    rotation: FloatArray,
    omega_radps: FloatArray,
    thrust_n: FloatArray,
    torque_nm: FloatArray,
    mass_kg: FloatArray,
    inertia_kgm2: FloatArray,
    dt_s: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Pure variant of rk4_step: returns new (position, velocity, rotation, omega)."""
    p, v, r, w = position_m.copy(), velocity_mps.copy(), rotation.copy(), omega_radps.copy()
    rk4_step(p, v, r, w, thrust_n, torque_nm, mass_kg, inertia_kgm2, dt_s)
    return p, v, r, w


@njit(cache=True)
def specific_force_body(thrust_n: FloatArray, mass_kg: FloatArray) -> FloatArray:
    """Accelerometer reading in body FLU (n, 3): (0, 0, T/m) for this drag-free model."""
    out = np.zeros((thrust_n.shape[0], 3))
    for i in range(thrust_n.shape[0]):
        out[i, 2] = thrust_n[i] / mass_kg[i]
    return out


# --- mixer (51): [T, tau_x, tau_y, tau_z] = M f,  M = [[1,1,1,1],[0,-d,0,d],[d,0,-d,0],[C,-C,C,-C]]


@njit(cache=True)
def max_collective_thrust_n(rotor_thrust_max_n: FloatArray) -> FloatArray:
    """Largest collective thrust, 4 f_max (scalar or per vehicle)."""
    return 4.0 * rotor_thrust_max_n


@njit(cache=True)
def wrench_from_rotors(
    rotor_thrust_n: FloatArray, arm_length_m: FloatArray, anti_torque_m: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Eq (51): rotor thrusts f (n, 4) -> (thrust_n (n,), torque_nm (n, 3) body FLU)."""
    n = rotor_thrust_n.shape[0]
    thrust_n = np.empty(n)
    torque_nm = np.empty((n, 3))
    for i in range(n):
        f1, f2 = rotor_thrust_n[i, 0], rotor_thrust_n[i, 1]
        f3, f4 = rotor_thrust_n[i, 2], rotor_thrust_n[i, 3]
        thrust_n[i] = f1 + f2 + f3 + f4
        torque_nm[i, 0] = arm_length_m[i] * (f4 - f2)
        torque_nm[i, 1] = arm_length_m[i] * (f1 - f3)
        torque_nm[i, 2] = anti_torque_m[i] * (f1 - f2 + f3 - f4)
    return thrust_n, torque_nm


@njit(cache=True)
def rotors_from_wrench_into(
    thrust_n: FloatArray,
    torque_nm: FloatArray,
    arm_length_m: FloatArray,
    anti_torque_m: FloatArray,
    rotor_thrust_max_n: FloatArray,
    out_rotor_thrust_n: FloatArray,
    airmode: FloatArray,
    out_limited: FloatArray,
) -> int:
    """Invert (51) into out (n, 4) with every rotor in [0, f_max]; returns how many vehicles'
    wrenches could not be met exactly. ``out_limited`` (n, 3) gets, per torque axis (FLU), +1
    where the torque made is below the demand, -1 where above, 0 where it is the demand: the
    saturation the autopilots' rate loops read to stop their integrators winding up (PX4's
    control-allocator saturation flags, ArduPilot's motor limit flags).

    `airmode` (n,) selects what gives way when the torque does not fit at a LOW collective
    thrust, like PX4's MC_AIRMODE: 0 (PX4's default) keeps the thrust and shrinks the torque
    (yaw first, then roll and pitch together); 1 raises the thrust to make room for roll/pitch,
    as described next. Above, at high thrust, both reduce the thrust.

    Write f = c + (p, q, -p, -q) + y (1, -1, 1, -1) with c = T/4, p = tau_y/(2d), q = -tau_x/(2d),
    y = tau_z/(4C) (the exact inverse). The limits decouple: c + y in [|p|, f_max - |p|] and
    c - y in [|q|, f_max - |q|]. Priority: roll/pitch, then thrust, then yaw:
    (1) if 2 max(|p|, |q|) > f_max, scale p and q by the same factor (torque direction kept);
    (2) clip c to the range where some yaw between 0 and y fits (thrust gives way; yaw may
    shrink but never flips sign); (3) clip y to the headroom left at that c (yaw gives way).
    A feasible wrench is returned exactly.
    Finally each rotor is clipped to [0, f_max] (only removes rounding). Needs d, C, f_max > 0.
    """
    n = thrust_n.shape[0]
    modified = 0
    for i in range(n):
        f_max = rotor_thrust_max_n[i]
        p = torque_nm[i, 1] / (2.0 * arm_length_m[i])
        q = -torque_nm[i, 0] / (2.0 * arm_length_m[i])
        c = 0.25 * thrust_n[i]
        y = torque_nm[i, 2] / (4.0 * anti_torque_m[i])
        changed = False
        spread = 2.0 * max(abs(p), abs(q))
        if spread > f_max:
            p *= f_max / spread
            q *= f_max / spread
            changed = True
        ap, aq = abs(p), abs(q)
        # Thrust range over which some yaw between 0 and the demand y fits (yaw never flips).
        y1, y2 = min(0.0, y), max(0.0, y)
        y_at_lo = min(max(0.5 * (ap - aq), y1), y2)
        y_at_hi = min(max(0.5 * (aq - ap), y1), y2)
        c_lo = max(ap - y_at_lo, aq + y_at_lo)
        c_hi = min(f_max - ap - y_at_hi, f_max - aq + y_at_hi)
        if airmode[i] == 0.0 and c < c_lo:
            # Thrust first: at this c the lower limits need c + y >= |p| and c - y >= |q|,
            # so |p| + |q| <= 2c; shrink roll/pitch to fit, then yaw to the range left.
            room = 2.0 * max(c, 0.0)
            if ap + aq > room:
                k = room / (ap + aq)
                p, q, ap, aq = p * k, q * k, ap * k, aq * k
            c_new = max(c, 0.0)
            changed = True
        else:
            c_new = min(max(c, c_lo), c_hi)
        y_lo = max(ap - c_new, c_new - (f_max - aq))
        y_hi = min(f_max - ap - c_new, c_new - aq)
        y_new = min(max(y, y_lo), y_hi)
        if changed or c_new != c or y_new != y:
            modified += 1
        out_rotor_thrust_n[i, 0] = min(max(c_new + p + y_new, 0.0), f_max)
        out_rotor_thrust_n[i, 1] = min(max(c_new + q - y_new, 0.0), f_max)
        out_rotor_thrust_n[i, 2] = min(max(c_new - p + y_new, 0.0), f_max)
        out_rotor_thrust_n[i, 3] = min(max(c_new - q - y_new, 0.0), f_max)
        # what each axis got against what it asked for (tau_x = -2 d q, tau_y = 2 d p, tau_z =
        # 4 C y); a relative tolerance so that rounding is not saturation
        d2 = 2.0 * arm_length_m[i]
        made = (-d2 * q, d2 * p, 4.0 * anti_torque_m[i] * y_new)
        for k in range(3):
            gap = torque_nm[i, k] - made[k]
            tol = 1e-9 * (abs(torque_nm[i, k]) + 1e-12)
            out_limited[i, k] = 1.0 if gap > tol else (-1.0 if gap < -tol else 0.0)
    return modified


@njit(cache=True)
def rotors_from_wrench(
    thrust_n: FloatArray,
    torque_nm: FloatArray,
    arm_length_m: FloatArray,
    anti_torque_m: FloatArray,
    rotor_thrust_max_n: FloatArray,
) -> FloatArray:
    """Rotor thrusts f (n, 4) for a wrench; see rotors_from_wrench_into for the clipping rule."""
    out = np.empty((thrust_n.shape[0], 4))
    airmode = np.ones(thrust_n.shape[0])
    rotors_from_wrench_into(
        thrust_n, torque_nm, arm_length_m, anti_torque_m, rotor_thrust_max_n, out, airmode,
        np.empty((thrust_n.shape[0], 3)),
    )
    return out
