"""Friction models of the wet multi-plate clutches and brakes (thesis section 2.2, eqs. 2.59-2.70).

Every model exists twice with the same argument list: ``<name>_sym`` builds a SymPy expression
from nothing but ``Piecewise``, ``sign``, ``Abs``, ``exp``, ``sin``, ``Max`` and powers, so the C
and CasADi emitters can print it; ``<name>_num`` is an independent NumPy implementation (scalars or
broadcasting arrays) for simulation and for cross-checking the symbolic one.

Sign convention of the project: a shift element between shafts a and b has the slip
``dw = w_a - w_b``; its torque ``T`` acts ``+T`` on shaft b and ``-T`` on shaft a (a brake has
a = housing, ``w_a = 0``). The power the element takes out of the shafts is therefore ``T * dw``,
and a sliding element has ``T`` of the sign of ``dw``.

Where the thesis is ambiguous or slipped (see SPEC.md "Known slips") this module does:

* (2.62): ``F_C`` inside the Stribeck curve is the magnitude ``mu_C F_N``; (2.63) supplies the sign.
* (2.63) at ``dw = 0``: the friction force is the stiction law (2.60), i.e. ``F_A`` limited to the
  break-away force ``mu_S F_N``, as in the kinetic model of the thesis' source [1].
* (2.64) Dahl is a differential equation: its left side is ``dF/dt``.
* (2.65): ``F_SS`` carries the sign of ``dw``; with a magnitude ``f_ss`` this is
  ``dz/dt = dw - sigma0 |dw| z / f_ss``.
* (2.66): ``alpha(z, dw)`` as in Dupont, Hayward, Armstrong, Altpeter 2002 (IEEE TAC 47(5)),
  written with ``|z|`` and the speed-dependent ``z_ss = |T_SS(dw)| / sigma0``; the break-away
  deflection is ``z_ba = z_ba_ratio * z_ss`` with ``0 <= z_ba_ratio < 1``.
* (2.68) with (2.70): ``alpha > 0`` only where ``sign z = sign dw``, and there
  ``k_sign = sign z``, so ``sigma0 z / T_SS = sigma0 |z| / |T_SS|``. The ``|z|`` form is used
  because (2.70) gives ``k_sign = 0`` at ``z = dw = 0`` (a closed element at rest), where the
  printed form evaluates ``0 / 0``.

Regularisations of the shift element (2.67)-(2.69), needed by a simulator:

* Open element (``F_N = 0``, also ``F_N < 0`` or ``mu = 0``): the capacity used in (2.68) is
  ``max(|T_SS|, t_ss_min)`` with ``t_ss_min = T_SS_MIN = 1e-3 N m``, about 1e-6 of a shift
  element's capacity (100-1000 N m) and far below the oil-shear drag of an open wet clutch
  (typically of order 1 N m), so it changes no physics: an open element transmits at most
  ``t_ss_min``. The price is a fast but linear relaxation ``|dw| sigma0 / t_ss_min`` of the
  bristle, which implicit integrators handle (the model is stiff through ``sigma0`` anyway).
* Over-deflected bristle (``|z| > z_ss`` after ``F_N`` or ``mu`` dropped): (2.68) relaxes ``z``
  towards ``z_ss``, but the literal damping term ``sigma1 dz/dt`` of (2.67) then points along the
  slip and the element would deliver energy (for ``|dw| > sigma0 |z| r / (sigma1 (r - 1))`` with
  ``r = alpha |z| / z_ss``). The damping term is therefore ``sigma1 dw max(0, 1 - r)``: identical to
  (2.67) whenever ``|z| <= z_ss`` (all normal operation), zero while the bristle relaxes. With
  it, ``T dw - d/dt(sigma0 z^2 / 2) = sigma0 |z| |dw| r + sigma1 dw^2 max(0, 1 - r) >= 0``: the
  element is passive with storage ``V = sigma0 z^2 / 2``.
* At exactly ``dw = 0`` the bristle keeps its deflection (``dz/dt`` is proportional to ``dw``, as
  in Dupont 2002). Dupont's model assumes a constant normal force: when the capacity drops
  below ``sigma0 |z|`` of a sticking element, (2.67) would keep transmitting ``sigma0 z`` at zero
  slip for ever (an equilibrium of the literal equations, seen in the 2-3 reference simulation
  when K38's pressure is lowered). The elastic term is therefore limited to the capacity,
  ``sat(sigma0 z, |T_SS|)``: the unbalanced torque makes the element slip at once, and the
  bristle relaxes. Passivity still holds: while over-deflected with ``sign z = sign dw`` the
  dissipation is ``|T_SS| |dw| + sigma0 |z| |dw| (r - 1) >= 0``; with ``sign z != sign dw``
  it is ``(sigma0 |z| - |T_SS|) |dw| + sigma1 dw^2 >= 0``.
"""

from __future__ import annotations

import hashlib
import re
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

import numpy as np
import sympy as sp
from gearsym.symbolic.errors import GearsymError
from gearsym.symbolic.io.input_files import parse_toml, read_text
from gearsym.symbolic.io.package_data import data_file
from numpy.typing import ArrayLike

if TYPE_CHECKING:
    from gearsym.symbolic.description import GearboxDescription

Num = float | np.ndarray
"""Numeric result: a NumPy scalar (``np.float64`` is a ``float``) or an array."""
Sym = sp.Expr | float
"""Symbolic argument: a SymPy expression or a plain number."""

T_SS_MIN = 1e-3
"""Floor of the steady-state torque magnitude in (2.68) [N m]; see the module docstring."""

DEFAULT_MU_MAP = data_file("mu_map_default.toml")
"""The default friction-coefficient map shipped with the project (package data)."""

MU_MAP = sp.Function("mu_map")
"""Placeholder ``mu_map(p_N, T_oil, dw)`` for code generation; evaluated with ``|dw|``."""


def _out(x: ArrayLike) -> Num:
    # 0-d arrays become NumPy scalars so scalar callers get a float, array callers an array.
    return np.asarray(x, dtype=float)[()]


# --------------------------------------------------------------------------------------------
# Static models (2.59)-(2.63)
# --------------------------------------------------------------------------------------------


def coulomb_sym(dw: Sym, f_n: Sym, mu_c: Sym) -> sp.Expr:
    """Coulomb friction ``F_C = F_N mu_C sign(dw)`` (2.59)."""
    return f_n * mu_c * sp.sign(dw)


def coulomb_num(dw: ArrayLike, f_n: ArrayLike, mu_c: ArrayLike) -> Num:
    """Numeric Coulomb friction (2.59)."""
    return _out(np.multiply(f_n, mu_c) * np.sign(dw))


def stiction_sym(f_a: Sym, f_n: Sym, mu_s: Sym) -> sp.Expr:
    """Static friction at ``dw = 0`` (2.60): ``F_A`` below the break-away force ``mu_S F_N``,
    else ``mu_S F_N sign(F_A)``; ``F_A`` is the sum of the external forces."""
    f_a = sp.sympify(f_a)
    limit = f_n * mu_s
    return sp.Piecewise((f_a, sp.Abs(f_a) < limit), (limit * sp.sign(f_a), True))


def stiction_num(f_a: ArrayLike, f_n: ArrayLike, mu_s: ArrayLike) -> Num:
    """Numeric static friction (2.60)."""
    f_a = np.asarray(f_a, dtype=float)
    limit = np.multiply(f_n, mu_s)
    return _out(np.where(np.abs(f_a) < limit, f_a, limit * np.sign(f_a)))


def viscous_sym(dw: Sym, nu: Sym, delta_v: Sym) -> sp.Expr:
    """Viscous friction ``F_V = nu |dw|^delta_V sign(dw)`` (2.61)."""
    return nu * sp.Abs(dw) ** delta_v * sp.sign(dw)


def viscous_num(dw: ArrayLike, nu: ArrayLike, delta_v: ArrayLike) -> Num:
    """Numeric viscous friction (2.61)."""
    return _out(np.multiply(nu, np.abs(dw) ** delta_v) * np.sign(dw))


def stribeck_sym(dw: Sym, f_n: Sym, mu_c: Sym, mu_s: Sym, omega_s: Sym, delta_s: Sym) -> sp.Expr:
    """Stribeck curve (2.62), a magnitude:
    ``mu_C F_N + F_N (mu_S - mu_C) exp(-(|dw| / omega_S)^delta_S)``.

    It equals ``mu_S F_N`` at ``dw = 0`` and tends to ``mu_C F_N`` for ``|dw| >> omega_S``.
    """
    return f_n * (mu_c + (mu_s - mu_c) * sp.exp(-((sp.Abs(dw) / omega_s) ** delta_s)))


def stribeck_num(
    dw: ArrayLike,
    f_n: ArrayLike,
    mu_c: ArrayLike,
    mu_s: ArrayLike,
    omega_s: ArrayLike,
    delta_s: ArrayLike,
) -> Num:
    """Numeric Stribeck curve (2.62), a magnitude."""
    decay = np.exp(-((np.abs(dw) / np.asarray(omega_s, dtype=float)) ** delta_s))
    return _out(np.multiply(f_n, mu_c + np.subtract(mu_s, mu_c) * decay))


def kinetic_sym(
    dw: Sym,
    f_a: Sym,
    f_n: Sym,
    mu_c: Sym,
    mu_s: Sym,
    omega_s: Sym,
    delta_s: Sym,
    nu: Sym,
    delta_v: Sym,
) -> sp.Expr:
    """Kinetic friction model (2.63): stiction (2.60) at ``dw = 0``, otherwise
    ``F_Stribeck sign(dw) + F_V`` from (2.62) and (2.61)."""
    sliding = stribeck_sym(dw, f_n, mu_c, mu_s, omega_s, delta_s) * sp.sign(dw)
    sliding += viscous_sym(dw, nu, delta_v)
    return sp.Piecewise((stiction_sym(f_a, f_n, mu_s), sp.Eq(dw, 0)), (sliding, True))


def kinetic_num(
    dw: ArrayLike,
    f_a: ArrayLike,
    f_n: ArrayLike,
    mu_c: ArrayLike,
    mu_s: ArrayLike,
    omega_s: ArrayLike,
    delta_s: ArrayLike,
    nu: ArrayLike,
    delta_v: ArrayLike,
) -> Num:
    """Numeric kinetic friction model (2.63)."""
    sliding = stribeck_num(dw, f_n, mu_c, mu_s, omega_s, delta_s) * np.sign(dw)
    sliding = sliding + viscous_num(dw, nu, delta_v)
    return _out(np.where(np.asarray(dw) == 0, stiction_num(f_a, f_n, mu_s), sliding))


# --------------------------------------------------------------------------------------------
# Dynamic models (2.64)-(2.66)
# --------------------------------------------------------------------------------------------


def dahl_sym(f: Sym, dw: Sym, f_c: Sym, sigma0: Sym, beta: Sym) -> sp.Expr:
    """Dahl model (2.64), returns ``dF/dt`` (the printed equation drops the derivative):
    ``sigma0 |1 - F/F_C sign(dw)|^beta sign(1 - F/F_C sign(dw)) dw``.

    ``f_c`` is the Coulomb magnitude ``mu_C F_N > 0``; ``F`` tends to ``f_c sign(dw)``.
    """
    s = 1 - f / f_c * sp.sign(dw)
    return sigma0 * sp.Abs(s) ** beta * sp.sign(s) * dw


def dahl_num(
    f: ArrayLike, dw: ArrayLike, f_c: ArrayLike, sigma0: ArrayLike, beta: ArrayLike
) -> Num:
    """Numeric Dahl model (2.64), returns ``dF/dt``."""
    s = 1 - np.divide(f, f_c) * np.sign(dw)
    return _out(np.multiply(sigma0, np.abs(s) ** beta) * np.sign(s) * dw)


def lugre_sym(
    z: Sym, dw: Sym, f_ss: Sym, sigma0: Sym, sigma1: Sym, sigma2: Sym = 0
) -> tuple[sp.Expr, sp.Expr]:
    """LuGre model (2.65), returns ``(dz/dt, F)``.

    ``dz/dt = dw (1 - sigma0 z / F_SS)`` with ``F_SS = f_ss sign(dw)``, i.e.
    ``dw - sigma0 |dw| z / f_ss``; ``F = sigma0 z + sigma1 dz/dt + sigma2 dw``. ``f_ss > 0`` is the
    steady-state friction magnitude (e.g. the Stribeck curve (2.62)).
    """
    zdot = dw - sigma0 * sp.Abs(dw) * z / f_ss
    return zdot, sigma0 * z + sigma1 * zdot + sigma2 * dw


def lugre_num(
    z: ArrayLike,
    dw: ArrayLike,
    f_ss: ArrayLike,
    sigma0: ArrayLike,
    sigma1: ArrayLike,
    sigma2: ArrayLike = 0.0,
) -> tuple[Num, Num]:
    """Numeric LuGre model (2.65), returns ``(dz/dt, F)``."""
    zdot = dw - np.multiply(sigma0, np.abs(dw)) * np.divide(z, f_ss)
    force = np.multiply(sigma0, z) + np.multiply(sigma1, zdot) + np.multiply(sigma2, dw)
    return _out(zdot), _out(force)


def ep_alpha_sym(z: Sym, dw: Sym, z_ss: Sym, z_ba: Sym) -> sp.Expr:
    """``alpha(z, dw)`` of the elasto-plastic model (2.66) after Dupont et al. 2002.

    0 where ``sign z != sign dw``; 0 for ``|z| <= z_ba``;
    ``1/2 sin(pi (|z| - (z_ss + z_ba)/2) / (z_ss - z_ba)) + 1/2`` for ``z_ba < |z| < z_ss``;
    1 beyond. ``z_ss = |T_SS(dw)| / sigma0`` and ``0 <= z_ba < z_ss`` (both positive numbers).
    """
    z, dw = sp.sympify(z), sp.sympify(dw)
    az = sp.Abs(z)
    ramp = sp.sin(sp.pi * (az - (z_ss + z_ba) / 2) / (z_ss - z_ba)) / 2 + sp.Rational(1, 2)
    return sp.Piecewise(
        (0, z * dw <= 0),  # product <= 0 covers sign z != sign dw, z = 0 and dw = 0
        (0, az <= z_ba),
        (ramp, az < z_ss),
        (1, True),
    )


def ep_alpha_num(z: ArrayLike, dw: ArrayLike, z_ss: ArrayLike, z_ba: ArrayLike) -> Num:
    """Numeric ``alpha(z, dw)`` of (2.66), see :func:`ep_alpha_sym`."""
    z = np.asarray(z, dtype=float)
    z_ss = np.asarray(z_ss, dtype=float)
    az = np.abs(z)
    ramp = 0.5 * np.sin(np.pi * (az - 0.5 * (z_ss + z_ba)) / (z_ss - z_ba)) + 0.5
    alpha = np.where(az <= z_ba, 0.0, np.where(az < z_ss, ramp, 1.0))
    return _out(np.where(z * np.asarray(dw) > 0, alpha, 0.0))


def elastoplastic_sym(
    z: Sym, dw: Sym, f_ss: Sym, sigma0: Sym, sigma1: Sym, z_ba_ratio: Sym, sigma2: Sym = 0
) -> tuple[sp.Expr, sp.Expr]:
    """Elasto-plastic model (2.66) with ``i = 1``, returns ``(dz/dt, F)``.

    ``dz/dt = dw (1 - r)``, ``r = alpha(z, dw) sigma0 |z| / f_ss`` (equal to the printed form, see
    the module docstring); ``F = sigma0 z + sigma1 dw max(0, 1 - r) + sigma2 dw``, which is the
    LuGre force ``sigma0 z + sigma1 dz/dt + sigma2 dw`` while ``|z| <= z_ss`` and drops the damping
    term of an over-deflected bristle so the model stays passive. ``f_ss > 0`` is the
    steady-state magnitude, ``z_ss = f_ss / sigma0``, ``z_ba = z_ba_ratio z_ss``.
    """
    z_ss = f_ss / sigma0
    r = ep_alpha_sym(z, dw, z_ss, z_ba_ratio * z_ss) * sp.Abs(z) / z_ss
    zdot = dw * (1 - r)
    # the bristle force never exceeds the capacity (see the module docstring)
    elastic = sp.Piecewise((f_ss * sp.sign(z), sp.Abs(z) > z_ss), (sigma0 * z, True))
    return zdot, elastic + sigma1 * dw * sp.Max(0, 1 - r) + sigma2 * dw


def elastoplastic_num(
    z: ArrayLike,
    dw: ArrayLike,
    f_ss: ArrayLike,
    sigma0: ArrayLike,
    sigma1: ArrayLike,
    z_ba_ratio: float,
    sigma2: ArrayLike = 0.0,
) -> tuple[Num, Num]:
    """Numeric elasto-plastic model (2.66), returns ``(dz/dt, F)``; see
    :func:`elastoplastic_sym`. Raises ``ValueError`` unless ``0 <= z_ba_ratio < 1``."""
    if not 0.0 <= z_ba_ratio < 1.0:
        raise ValueError(f"z_ba_ratio must be in [0, 1), got {z_ba_ratio}")
    z_ss = np.divide(f_ss, sigma0)
    r = ep_alpha_num(z, dw, z_ss, z_ba_ratio * z_ss) * np.abs(z) / z_ss
    zdot = np.multiply(dw, 1.0 - r)
    force = (
        np.clip(np.multiply(sigma0, z), -np.asarray(f_ss), np.asarray(f_ss))
        + np.multiply(sigma1, dw) * np.maximum(0.0, 1.0 - r)
        + np.multiply(sigma2, dw)
    )
    return _out(zdot), _out(force)


# --------------------------------------------------------------------------------------------
# Shift-element torque (2.67)-(2.70)
# --------------------------------------------------------------------------------------------


def normal_force(p_n: Sym | ArrayLike, a_disc: Sym | ArrayLike) -> Sym | Num:
    """Normal force on the disc pack ``F_N = p_N A_disc`` (text below (2.70)); works on
    SymPy expressions and on numbers/arrays alike."""
    if isinstance(p_n, sp.Basic) or isinstance(a_disc, sp.Basic):
        return p_n * a_disc
    return _out(np.multiply(p_n, a_disc))


def k_sign_sym(dw: Sym, z: Sym) -> sp.Expr:
    """``k_sign(dw, z)`` (2.70): ``sign(z)`` for ``z != 0``, else ``sign(dw)``."""
    z = sp.sympify(z)
    return sp.Piecewise((sp.sign(z), sp.Ne(z, 0)), (sp.sign(dw), True))


def k_sign_num(dw: ArrayLike, z: ArrayLike) -> Num:
    """Numeric ``k_sign`` (2.70)."""
    z = np.asarray(z, dtype=float)
    return _out(np.where(z != 0, np.sign(z), np.sign(dw)))


def t_cl_ss_sym(dw: Sym, z: Sym, f_n: Sym, mu: Sym, n_disc: Sym, r_m: Sym) -> sp.Expr:
    """Signed steady-state torque ``T_Cl,SS = k_sign(dw, z) 2 N_disc r_m mu F_N`` (2.69)."""
    return k_sign_sym(dw, z) * 2 * n_disc * r_m * mu * f_n


def t_cl_ss_num(
    dw: ArrayLike, z: ArrayLike, f_n: ArrayLike, mu: ArrayLike, n_disc: ArrayLike, r_m: ArrayLike
) -> Num:
    """Numeric signed steady-state torque (2.69)."""
    return _out(k_sign_num(dw, z) * 2.0 * np.multiply(n_disc, r_m) * np.multiply(mu, f_n))


def shift_element_sym(
    z: Sym,
    dw: Sym,
    f_n: Sym,
    mu: Sym,
    sigma0: Sym,
    sigma1: Sym,
    n_disc: Sym,
    r_m: Sym,
    z_ba_ratio: Sym,
    t_ss_min: Sym = T_SS_MIN,
) -> tuple[sp.Expr, sp.Expr]:
    """Bristle rate and torque ``(dz/dt, T_Cl)`` of a shift element, (2.66)-(2.70).

    ``T_Cl = sigma0 z + sigma1 dz/dt`` (2.67), ``dz/dt = dw (1 - alpha sigma0 z / T_Cl,SS)`` (2.68),
    ``|T_Cl,SS| = 2 N_disc r_m mu F_N`` (2.69), sign by ``k_sign`` (2.70). ``dw = w_a - w_b``; the
    torque acts ``+T_Cl`` on shaft b and ``-T_Cl`` on shaft a. ``mu`` may be a symbol or
    ``MuMap.symbolic(p_N, T_oil, dw)``; ``f_n`` may be ``normal_force(p_N, A_disc)``.

    Degenerate cases (module docstring): the capacity is floored at ``t_ss_min`` so an open
    element (``F_N = 0``) needs no division by zero, and the damping term is dropped while an
    over-deflected bristle (``|z| > z_ss`` after ``F_N`` fell) relaxes, so the element is passive.
    """
    capacity = sp.Max(2 * n_disc * r_m * mu * f_n, t_ss_min)
    return elastoplastic_sym(z, dw, capacity, sigma0, sigma1, z_ba_ratio)


def shift_element_num(
    z: ArrayLike,
    dw: ArrayLike,
    f_n: ArrayLike,
    mu: ArrayLike,
    sigma0: ArrayLike,
    sigma1: ArrayLike,
    n_disc: ArrayLike,
    r_m: ArrayLike,
    z_ba_ratio: float,
    t_ss_min: float = T_SS_MIN,
) -> tuple[Num, Num]:
    """Numeric ``(dz/dt, T_Cl)`` of a shift element, (2.66)-(2.70); see
    :func:`shift_element_sym` for conventions and regularisation."""
    capacity = np.maximum(2.0 * np.multiply(n_disc, r_m) * np.multiply(mu, f_n), t_ss_min)
    return elastoplastic_num(z, dw, capacity, sigma0, sigma1, z_ba_ratio)


def one_way_sym(
    z: Sym, dw: Sym, locks: int, stiffness: Sym, damping: Sym
) -> tuple[sp.Expr, sp.Expr]:
    """One-way clutch (freewheel) as a stiff, damped unilateral spring; returns ``(dz/dt, T)``.

    Not in the thesis (its gearbox has no freewheel); built like the bristle of (2.66)-(2.67)
    with the sign rule of (2.70). ``locks`` = +1 blocks ``dw > 0``, −1 blocks ``dw < 0``;
    ``v = locks dw`` is the slip towards the blocked side. ``z`` is the wind-up of the sprags
    into the blocked direction (``z > 0``: in contact):

    * ``dz/dt = v`` while in contact (``z > 0``) or closing (``v > 0``), else 0: overrunning,
      the freewheel keeps no memory of the free travel, so it locks the moment the slip crosses
      zero into the blocked direction;
    * ``T = locks max(0, stiffness z + damping dz/dt)``: a contact pushes, never pulls, so the
      torque has the blocked sign or is zero (no drag torque while overrunning).

    Passive with storage ``V = stiffness max(z, 0)^2 / 2``: ``T dw − dV/dt`` is ``damping v^2``
    in contact, ``−stiffness z v > 0`` while a contact opens faster than the spring relaxes,
    and ``T dw >= 0`` otherwise.
    """
    z = sp.sympify(z)
    v = locks * sp.sympify(dw)
    zdot = sp.Piecewise((v, sp.Or(z > 0, v > 0)), (0, True))
    return zdot, locks * sp.Max(0, stiffness * z + damping * zdot)


def one_way_num(
    z: ArrayLike, dw: ArrayLike, locks: int, stiffness: ArrayLike, damping: ArrayLike
) -> tuple[Num, Num]:
    """Numeric one-way clutch, see :func:`one_way_sym`."""
    z = np.asarray(z, dtype=float)
    v = locks * np.asarray(dw, dtype=float)
    zdot = np.where((z > 0) | (v > 0), v, 0.0)
    force = np.maximum(0.0, np.multiply(stiffness, z) + np.multiply(damping, zdot))
    return _out(zdot), _out(locks * force)


# --------------------------------------------------------------------------------------------
# Friction-coefficient map mu(p_N, T_oil, dw), used in (2.69)
# --------------------------------------------------------------------------------------------


class MuMap:
    """Friction coefficient ``mu(p_N, T_oil, |dw|)`` on a regular grid (used in (2.69)).

    Numeric evaluation (``__call__``) is trilinear and clamped to the grid edges (no
    extrapolation of measured data); ``dw`` enters as ``|dw|``. For code generation
    :meth:`symbolic` returns the placeholder ``mu_map(p_N, T_oil, dw)``; to evaluate such an
    expression numerically, lambdify with ``modules=[{"mu_map": the_map}, "numpy"]``.
    Construction raises ``ValueError("<origin>: <key>: <reason>")`` for an invalid grid.
    """

    AXES: tuple[tuple[str, str], ...] = (("p_N", "Pa"), ("T_oil", "degC"), ("dw", "rad/s"))
    """Axis keys and the units the map must be given in (no silent unit conversion)."""

    def __init__(
        self,
        p_n: ArrayLike,
        t_oil: ArrayLike,
        dw: ArrayLike,
        mu: ArrayLike,
        origin: str = "<arrays>",
    ) -> None:
        self.origin = origin
        grid = []
        for (name, _), values in zip(self.AXES, (p_n, t_oil, dw), strict=True):
            axis = _float_array(values, origin, f"axes.{name}.values")
            if axis.ndim != 1 or axis.size < 2:
                _fail(origin, f"axes.{name}.values", "need a list of at least 2 numbers")
            if not np.all(np.diff(axis) > 0):
                _fail(origin, f"axes.{name}.values", "axis values must be strictly increasing")
            grid.append(axis)
        if grid[2][0] < 0:
            _fail(origin, "axes.dw.values", "slip axis must be >= 0 (the map is read with |dw|)")
        table = _float_array(mu, origin, "mu.values")
        shape = tuple(a.size for a in grid)
        if table.shape != shape:
            _fail(origin, "mu.values", f"wrong shape {table.shape}, expected {shape}")
        if np.any(table < 0):
            _fail(origin, "mu.values", f"negative friction coefficient (min {table.min():g})")
        if np.any(table > 1):
            _fail(origin, "mu.values", f"implausible mu > 1 (max {table.max():g}); percent?")
        self.grid: tuple[np.ndarray, ...] = tuple(grid)
        self.table: np.ndarray = table
        self._interp: Any = None  # built on first call: `gearsym generate` only prints the table

    def _interpolator(self) -> Any:
        if self._interp is None:
            # imported on use: loading SciPy costs half a second
            from scipy.interpolate import RegularGridInterpolator

            self._interp = RegularGridInterpolator(self.grid, self.table, method="linear")
        return self._interp

    @classmethod
    def from_toml(cls, path: str | Path = DEFAULT_MU_MAP) -> MuMap:
        """Load a map file: tables ``axes.p_N``, ``axes.T_oil``, ``axes.dw`` and ``mu``, each
        with ``unit``, ``source`` and ``values``; ``mu.values[i][j][k] = mu(p_N[i], T_oil[j],
        dw[k])``. Units must be Pa, degC, rad/s and 1 (see ``AXES``)."""
        origin = str(path)
        try:
            doc = parse_toml(read_text(path, origin), origin)
        except GearsymError as err:  # unreadable, too large, not UTF-8 or not TOML
            _fail(origin, err.key or "<file>", f"cannot read TOML: {err.reason}")
        tables = {f"axes.{name}": (doc.get("axes", {}).get(name), unit) for name, unit in cls.AXES}
        tables["mu"] = (doc.get("mu"), "1")
        for key, (table, unit) in tables.items():
            if not isinstance(table, dict):
                _fail(origin, key, "missing table")
            if "unit" not in table:
                _fail(origin, f"{key}.unit", "missing unit")
            if table["unit"] != unit:
                _fail(origin, f"{key}.unit", f"unit {table['unit']!r} not supported, use {unit!r}")
            if not isinstance(table.get("source"), str) or not table["source"].strip():
                _fail(origin, f"{key}.source", "missing source")
            if "values" not in table:
                _fail(origin, f"{key}.values", "missing values")
        return cls(*(tables[key][0]["values"] for key in tables), origin=origin)

    def __call__(self, p_n: ArrayLike, t_oil: ArrayLike, dw: ArrayLike) -> Num:
        """Interpolated ``mu`` at ``(p_N, T_oil, |dw|)``, clamped to the grid; broadcasts."""
        pts = np.broadcast_arrays(
            np.asarray(p_n, dtype=float), np.asarray(t_oil, dtype=float), np.abs(dw)
        )
        shape = pts[0].shape
        clamped = [np.clip(x, g[0], g[-1]).ravel() for x, g in zip(pts, self.grid, strict=True)]
        return _out(self._interpolator()(np.stack(clamped, axis=-1)).reshape(shape))

    @staticmethod
    def symbolic(p_n: Sym, t_oil: Sym, dw: Sym) -> sp.Expr:
        """The undefined function ``mu_map(p_N, T_oil, dw)`` standing for the map in
        generated code (the implementation must use ``|dw|`` and clamp, like ``__call__``)."""
        return MU_MAP(p_n, t_oil, dw)


def _fail(origin: str, key: str, reason: str) -> NoReturn:
    # One line, naming file, key and reason, so the message is usable in logs and CI output.
    raise ValueError(f"{origin}: {key}: {' '.join(str(reason).split())}")


def _float_array(values: object, origin: str, key: str) -> np.ndarray:
    try:
        arr = np.asarray(values, dtype=float)
    except (TypeError, ValueError) as exc:
        # NumPy reports ragged nested lists as an inhomogeneous shape.
        _fail(origin, key, f"wrong shape or non-numeric entries ({exc})")
    if not np.all(np.isfinite(arr)):
        _fail(origin, key, "non-finite value")
    return arr


__all__ = [
    "DEFAULT_MU_MAP",
    "MU_MAP",
    "T_SS_MIN",
    "MuMap",
    "coulomb_num",
    "coulomb_sym",
    "dahl_num",
    "dahl_sym",
    "elastoplastic_num",
    "elastoplastic_sym",
    "ep_alpha_num",
    "ep_alpha_sym",
    "k_sign_num",
    "k_sign_sym",
    "kinetic_num",
    "kinetic_sym",
    "lugre_num",
    "lugre_sym",
    "normal_force",
    "one_way_num",
    "one_way_sym",
    "shift_element_num",
    "shift_element_sym",
    "stiction_num",
    "stiction_sym",
    "stribeck_num",
    "stribeck_sym",
    "t_cl_ss_num",
    "t_cl_ss_sym",
    "viscous_num",
    "viscous_sym",
]


def load_mu_map(d: GearboxDescription) -> MuMap:  # the one μ-map loader
    """The μ map the description names (``friction.mu_map``: "built-in" or a path relative to
    the description file); a bad map is a one-line :class:`GearsymError`.

    Its ``origin``, which the emitted files print, is :func:`mu_map_origin`: the file's name
    reduced to safe characters and the SHA-256 of its bytes, never a path.
    """
    if d.mu_map == "built-in":
        path = DEFAULT_MU_MAP
        label = "built-in"
    else:
        base = Path(d.file).parent if not d.file.startswith("<") else Path.cwd()
        path = base / d.mu_map
        label = ""
        if not path.is_file():
            raise GearsymError(d.file, "friction.mu_map", f"no such file: {d.mu_map}")
    try:
        data = path.read_bytes()
        mu_map = MuMap.from_toml(path)
    except OSError as err:
        raise GearsymError(d.file, "friction.mu_map", f"cannot read: {err.strerror}") from None
    except ValueError as err:
        raise GearsymError(d.file, "friction.mu_map", str(err)) from None
    mu_map.origin = mu_map_origin(path.name, data, label)
    return mu_map


_UNSAFE_NAME_CHARACTERS = re.compile(r"[^A-Za-z0-9._+-]")


def mu_map_origin(file_name: str, data: bytes, label: str = "") -> str:
    """``"[label ]<name> (SHA-256 <hex>)"``: the map's file name with every character outside
    ``[A-Za-z0-9._+-]`` replaced by ``_`` (so it needs no escaping in a C comment, a Python
    docstring or Markdown, and holds no directory), and the digest that identifies the data."""
    name = _UNSAFE_NAME_CHARACTERS.sub("_", Path(file_name).name) or "_"
    digest = hashlib.sha256(data).hexdigest()
    return f"{label + ' ' if label else ''}{name} (SHA-256 {digest})"
