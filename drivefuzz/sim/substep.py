"""The stages of one sub-step of the ego's vehicle model (:class:`drivefuzz.sim.physics.VehiclePhysics`):
the rear tyre's lateral force with the drive and brake forces, the front lateral force with the linearly
implicit lateral and yaw update, and the velocities. Moved out of ``physics.py`` unchanged (house style:
modules under 600 lines); ``VehiclePhysics._substeps`` calls them in this order. SI units, body frame x
forward, y left.
"""

from __future__ import annotations

from math import atan, cos, sin, sqrt


# Floor of the wheel-longitudinal speed in the slip-angle denominator [m/s].  The dynamic
# model only carries weight above ``kinematic_blend_low`` (>= this), so it only matters
# for a car sliding sideways (a spin), where it yields slip angles near +-90 deg.
_V_SLIP_MIN = 0.5


def tyre_forces(w: float, vx: float, vy: float, r: float, fzf: float, capf: float, capr: float,
                 rear: tuple, drive: tuple) -> tuple[float, ...]:
    """The rear lateral force and the drive and brake forces of one sub-step [N].

    Returns ``(Fy rear, d Fy rear / d vy [N s/m], front force along the wheel, front
    propulsion, front resistance, rear propulsion, rear resistance)``.  Lateral priority on
    the rear axle: the rear brakes and traction only get the friction the lateral force
    leaves, as EBD/ABS keep the rear stable (the front is longitudinal-priority, see
    :func:`lateral_dynamics`); no lateral force while the dynamic weight ``w`` is 0.
    Drive and EBD brakes are capped per axle (ideal ABS / TC); the propulsion and
    resistance parts are >= 0.  ``rear``: ``(B, C, E, lateral grip, max long. utilisation,
    lr)``; ``drive``: ``(max drive force x throttle, max power x throttle, front drive
    fraction, brake force, m g, max long. utilisation front)``.
    """
    Br, Cr, Er, gr_lat, util_r, lr = rear
    fmax, pmax, fdf, fbrake, mg, util_f = drive
    if w > 0.0:
        vlat_r = vy - lr * r
        Vr = vx if vx > 0.0 else -vx
        if Vr < _V_SLIP_MIN:
            Vr = _V_SLIP_MIN
        xb = -Br * atan(vlat_r / Vr)  # B * slip angle
        if Er == 0.0:
            u = xb
            du = Br
        else:
            u = xb - Er * (xb - atan(xb))
            du = Br * (1.0 - Er + Er / (1.0 + xb * xb))
        phi = Cr * atan(u)
        Dr = gr_lat * capr
        fyr = Dr * sin(phi)
        kr = Dr * Cr * cos(phi) * du / (1.0 + u * u)
        if kr < 0.0:
            kr = 0.0
        gr = -Vr / (Vr * Vr + vlat_r * vlat_r) * kr  # d alpha / d vy (approximate, ignores d|vlong|)
        left = capr * capr - fyr * fyr
        lim_r = util_r * sqrt(left) if left > 0.0 else 0.0
    else:
        fyr = gr = 0.0
        lim_r = util_r * capr
    lim_f = util_f * capf
    if fmax > 0.0:
        fd = pmax / vx if vx > 1.0 else pmax
        if fd > fmax:
            fd = fmax
    else:
        fd = 0.0
    dfa = fd * fdf
    dra = fd - dfa
    bfa = fbrake * fzf / mg
    bra = fbrake - bfa
    if vx >= 0.0:
        nf = dfa - bfa
        if nf > lim_f:
            nf = lim_f
        elif nf < -lim_f:
            nf = -lim_f
        nr = dra - bra
        if nr > lim_r:
            nr = lim_r
        elif nr < -lim_r:
            nr = -lim_r
        pf, qf = (nf, 0.0) if nf >= 0.0 else (0.0, -nf)
        pr_, qr = (nr, 0.0) if nr >= 0.0 else (0.0, -nr)
        return fyr, gr, nf, pf, qf, pr_, qr  # nf: the signed force along the wheel
    # rolling backwards (only after a spin): drive and brakes both push forward
    pf = dfa if dfa < lim_f else lim_f
    qf = bfa if bfa < lim_f - pf else lim_f - pf
    pr_ = dra if dra < lim_r else lim_r
    qr = bra if bra < lim_r - pr_ else lim_r - pr_
    return fyr, gr, pf + qf, pf, qf, pr_, qr


def lateral_dynamics(vx: float, vy: float, r: float, cd: float, sd: float, capf: float, fxf: float,
                      fyr: float, gr: float, front: tuple, body: tuple) -> tuple[float, float, float]:
    """``(Fy front [N], vy [m/s], yaw rate [rad/s])`` of the dynamic model after one sub-step.

    The front force is limited by the friction ellipse (the lateral capacity the
    longitudinal force ``fxf`` leaves); the lateral and yaw equations are linearly
    implicit (one Newton step of implicit Euler, tyre slopes clamped at >= 0; ``gr`` is
    the rear's).  ``front``: ``(B, C, E, lateral grip, lf)``; ``body``: ``(m, Iz, lf, lr,
    wind force, h)``.
    """
    Bf, Cf, Ef, gr_lat_f, lf = front
    m, iz, lf, lr, fw, h = body
    # front slip angle (wheel frame; valid for any direction of travel)
    vyf = vy + lf * r
    vlong_f = vx * cd + vyf * sd
    vlat_f = vyf * cd - vx * sd
    Vf = vlong_f if vlong_f > 0.0 else -vlong_f
    if Vf < _V_SLIP_MIN:
        Vf = _V_SLIP_MIN
    uf = fxf / capf
    Df = gr_lat_f * capf * sqrt(1.0 - uf * uf)
    xb = -Bf * atan(vlat_f / Vf)
    if Ef == 0.0:
        u = xb
        du = Bf
    else:
        u = xb - Ef * (xb - atan(xb))
        du = Bf * (1.0 - Ef + Ef / (1.0 + xb * xb))
    phi = Cf * atan(u)
    fyf = Df * sin(phi)
    kf = Df * Cf * cos(phi) * du / (1.0 + u * u)
    if kf < 0.0:
        kf = 0.0
    # lateral / yaw right-hand side (front forces in the body frame)
    fyf_b = fyf * cd + fxf * sd
    f1 = (fyf_b + fyr + fw) / m - vx * r
    f2 = (lf * fyf_b - lr * fyr) / iz
    # linearised tyre forces: d alpha / d vy (approximate, ignores d|vlong|)
    gf = -cd * Vf / (Vf * Vf + vlat_f * vlat_f) * kf * cd
    j11 = (gf + gr) / m
    j12 = (gf * lf - gr * lr) / m - vx
    j21 = (lf * gf - lr * gr) / iz
    j22 = (lf * lf * gf + lr * lr * gr) / iz
    a11 = 1.0 - h * j11
    a12 = -h * j12
    a21 = -h * j21
    a22 = 1.0 - h * j22
    det = a11 * a22 - a12 * a21
    if det > 0.05:
        dvy = h * (a22 * f1 - a12 * f2) / det
        dr = h * (a11 * f2 - a21 * f1) / det
    else:  # (near-)singular linearisation: explicit Euler
        dvy = h * f1
        dr = h * f2
    return fyf, vy + dvy, r + dr


def velocities(w: float, vx: float, vy: float, r: float, cd: float, sd: float, pf: float, qf: float,
                pr_: float, qr: float, fyf: float, vy_d: float, r_d: float,
                motion: tuple) -> tuple[float, float, float, float]:
    """``(vx, vy, yaw rate, ax)`` after one sub-step: the longitudinal speed, then the lateral
    states blended (weight ``w``) between the dynamic ones and the kinematic model.

    Longitudinal: propulsion, then the resistances without overshoot (they stop the car,
    never reverse it).  Kinematic: ``r = vx tan(delta) / L``, ``vy = lr r``, the pull
    towards it limited by the friction.  ``ax`` [m/s^2] only feeds the next load transfer.
    ``motion``: ``(m, drag factor, rolling resistance force, L, lr, max |d vy| and max |d r|
    per sub-step, h)``.
    """
    m, drag, rr, L, lr, kin_dvy, kin_dr, h = motion
    a_n = (pf * cd + pr_) / m
    if w > 0.0:
        # Coriolis term with the *updated* r, vy (symplectic Euler: the body-frame
        # velocity rotation neither gains nor loses energy, even in a fast spin)
        a_n += w * (r_d * vy_d - fyf * sd / m)
    a_res = (qf * cd + qr + drag * vx * vx + rr) / m
    v1 = vx + h * a_n
    if v1 > 0.0:
        vx_new = v1 - h * a_res
        if vx_new < 0.0:
            vx_new = 0.0
    else:
        vx_new = v1 + h * a_res
        if vx_new > 0.0:
            vx_new = 0.0
    if w < 1.0:
        r_k = vx_new * sd / (cd * L)
        dk = r_k * lr - vy
        if dk > kin_dvy:
            dk = kin_dvy
        elif dk < -kin_dvy:
            dk = -kin_dvy
        vy_k = vy + dk
        dk = r_k - r
        if dk > kin_dr:
            dk = kin_dr
        elif dk < -kin_dr:
            dk = -kin_dr
        r_k = r + dk
        if w > 0.0:
            vy_new = w * vy_d + (1.0 - w) * vy_k
            r_new = w * r_d + (1.0 - w) * r_k
        else:
            vy_new = vy_k
            r_new = r_k
    else:
        vy_new = vy_d
        r_new = r_d
    ax = (vx_new - vx) / h - r_new * vy_new
    if ax > 20.0:
        ax = 20.0
    elif ax < -20.0:
        ax = -20.0
    return vx_new, vy_new, r_new, ax
