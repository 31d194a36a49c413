"""The law's gains as one immutable record that numba-compiled code can take as an argument."""

from __future__ import annotations

from typing import NamedTuple

GRAVITY_MPS2 = 9.81


class LawGains(NamedTuple):
    """Gains of eqs. (21)-(27) (Section V of the paper) and of the body-rate variant.

    c_p: formation coupling in s_i (21) [1/s]; alpha_p: force feedback (23) [m/s^2];
    alpha_m: I&I estimator scale (24); sigma_a: saturation bound; alpha_eps, alpha_omega:
    attitude and rate feedback of the torque (26) [N m]; c_eps: cross term of (27);
    alpha_rho: inertia adaptation rate (27); k_eps: attitude feedback of the body-rate command
    [1/s] (rates mode; roll and pitch); k_eps_yaw: the same about the yaw axis (an autopilot's
    yaw is far slower than its roll and pitch); gravity_mps2: g; phi_horizontal: the weight
    w of the horizontal velocity in the estimator's phi_i (1: the paper's; 0: the vertical
    alone; position.phi).
    """

    c_p: float
    alpha_p: float
    alpha_m: float
    sigma_a: float
    alpha_eps: float
    alpha_omega: float
    c_eps: float
    alpha_rho: float
    k_eps: float
    k_eps_yaw: float
    gravity_mps2: float = GRAVITY_MPS2
    phi_horizontal: float = 1.0


#: The paper's Section V gains (with k_eps for the rates variant).
PAPER_GAINS = LawGains(
    c_p=4.0,
    alpha_p=2.0,
    alpha_m=1.0,
    sigma_a=1.0,
    alpha_eps=32.0,
    alpha_omega=32.0,
    c_eps=0.5,
    alpha_rho=0.5,
    k_eps=8.0,
    k_eps_yaw=8.0,
)
