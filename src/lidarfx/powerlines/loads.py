"""Conductor mechanics: predict a surveyed span's catenary under another load case.

A span is measured in the *survey state* (catenary parameter ``a = H / w``, horizontal
span length ``L``, height difference ``h`` from the start attachment point A to the end
attachment point B, conductor temperature at the survey, no ice, no wind).  The
change-of-state equation gives the horizontal tension ``H2`` under another load case
(temperature, ice, wind); the loaded curve lies in the plane through the chord AB that
contains the resultant load, swung out of the vertical by ``phi = atan2(w_h, w_v)``.

Span-local frame (the lidarfx convention, see :mod:`lidarfx.synth.powerline`):
``z(s) = c + a·cosh((s − s0)/a)``, ``s`` = horizontal distance from A towards B along the
plan chord; sag = distance chord–curve where the curve's slope equals the chord's slope
(``s_sag = s0 + a·asinh(h/L)``).  Units: m, N, N/mm², °C, kg; ``g = 9.80665``.

In the loaded plane the same formulas hold with the in-plane span ``X = sqrt(L² + h²·sin²φ)``
and height difference ``Y = h·cos φ`` (both equal L and h without wind); ``s = x·L/X``.
The equations, conductor data and their sources: ``docs/powerline-loads.md``.
"""
from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import LidarfxError, LidarfxWarning
from .catenary import catenary_through

__all__ = [
    "AIR_DENSITY", "CONDUCTORS", "Conductor", "G", "LoadCase", "SpanState", "catenary_sag",
    "conductor", "conductor_length", "loaded_curve", "mean_tension", "parse_load_case",
    "predict_span", "state_change", "state_change_parabolic", "support_tension", "unit_loads",
]

G = 9.80665
"""Standard gravity (m/s²)."""
AIR_DENSITY = 1.225
"""Air density (kg/m³) of the wind-speed conversion ``q = ½·ρ·v²``."""


def _items(text: str, what: str):
    seen = set()
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        key, sep, value = part.partition("=")
        if not sep or not key.strip():
            raise LidarfxError(f"{what} item {part!r} is not key=value")
        if key.strip().lower() in seen:
            raise LidarfxError(f"{what} key {key.strip().lower()!r} given twice")
        seen.add(key.strip().lower())
        yield key.strip().lower(), value.strip()


def _number(name: str, text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise LidarfxError(f"{name} must be a number, got {text!r}") from None
    if not math.isfinite(v):
        raise LidarfxError(f"{name} must be finite, got {text!r}")
    return v


def _finite(name: str, v: Any) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
            or not math.isfinite(v):
        raise LidarfxError(f"{name} must be a finite number, got {v!r}")


def _positive(name: str, v: Any) -> None:
    _finite(name, v)
    if v <= 0:
        raise LidarfxError(f"{name} must be > 0, got {v!r}")


@dataclass(frozen=True)
class Conductor:
    """A bare stranded conductor.

    ``diameter`` (m), ``area`` total cross-section (mm²), ``mass`` (kg/m), ``modulus`` final
    modulus of elasticity (N/mm²), ``alpha`` coefficient of linear expansion (1/K),
    ``rated_strength`` (kN, optional), ``source`` where the numbers come from."""

    name: str
    diameter: float
    area: float
    mass: float
    modulus: float
    alpha: float
    rated_strength: float | None = None
    source: str = ""

    def __post_init__(self):
        for key in ("diameter", "area", "mass", "modulus", "alpha"):
            _positive(f"conductor {key}", getattr(self, key))
        if self.rated_strength is not None:
            _positive("conductor rated_strength", self.rated_strength)

    @property
    def weight(self) -> float:
        """Weight per metre (N/m) = mass · g."""
        return self.mass * G

    @property
    def axial_stiffness(self) -> float:
        """E·A (N)."""
        return self.modulus * self.area


_EN50182 = "EN 50182:2001 Annex F, Table F.19 (Germany, AL1/ST1A)"
_ALCOA_DRAKE = ("Alcoa sag-and-tension data sheet for Drake (area 0.7264 in², dia 1.108 in, "
                "1.094 lb/ft, RTS 31 500 lb; ASTM B232 sizes); E and alpha: the EN 50182 "
                "Table F.19 values of the same 26/7 stranding")
_HAWK = ("ASTM B232 / manufacturers' catalogues (477 kcmil 26/7, dia 0.858 in, RBS 19 500 lb), "
         "nominal, not checked against a copy of the standard; E and alpha: the EN 50182 "
         "Table F.19 values of the same 26/7 stranding")

CONDUCTORS: dict[str, Conductor] = {c.name: c for c in (
    Conductor("ACSR Drake", 0.02814, 468.6, 1.628, 77000.0, 18.9e-6, 140.1, _ALCOA_DRAKE),
    Conductor("ACSR Hawk", 0.02179, 280.8, 0.976, 77000.0, 18.9e-6, 86.7, _HAWK),
    Conductor("243-AL1/39-ST1A", 0.0218, 282.5, 0.9801, 77000.0, 18.9e-6, 85.12, _EN50182),
    Conductor("264-AL1/34-ST1A", 0.0224, 297.7, 0.9944, 74000.0, 19.6e-6, 81.04, _EN50182),
    Conductor("434-AL1/56-ST1A", 0.0288, 490.6, 1.6413, 70000.0, 19.3e-6, 133.59, _EN50182),
)}
"""Built-in conductors by name (sources per entry in ``source`` and in the docs)."""


def _key(text: str) -> str:
    return re.sub(r"[\s_\-]+", "", text.lower())


_ALIASES: dict[str, str] = {
    **{_key(n): n for n in CONDUCTORS},
    "drake": "ACSR Drake", "acsrdrake795": "ACSR Drake",
    "hawk": "ACSR Hawk", "acsrhawk477": "ACSR Hawk",
    "240/40": "243-AL1/39-ST1A", "al/st240/40": "243-AL1/39-ST1A",
    "265/35": "264-AL1/34-ST1A", "al/st265/35": "264-AL1/34-ST1A", "265al1/35st1a": "264-AL1/34-ST1A",
    "435/55": "434-AL1/56-ST1A", "al/st435/55": "434-AL1/56-ST1A", "435al1/55st1a": "434-AL1/56-ST1A",
}
_SPEC_KEYS = ("mass", "area", "diameter", "modulus", "alpha")


def conductor(spec: Any) -> Conductor:
    """A :class:`Conductor` from a built-in name (case-insensitive: ``"drake"``,
    ``"ACSR Drake"``, ``"435/55"``, ``"434-AL1/56-ST1A"``, …) or a custom spec
    ``"mass=1.628,area=468.5,diameter=0.02812,modulus=74000,alpha=18.9e-6"`` (units of
    :class:`Conductor`; ``rated_strength`` (kN) and ``name`` optional); a Conductor passes."""
    if isinstance(spec, Conductor):
        return spec
    if not isinstance(spec, str) or not spec.strip():
        raise LidarfxError(f"conductor must be a name or a spec string, got {spec!r}")
    if "=" not in spec:
        name = _ALIASES.get(_key(spec))
        if name is None:
            raise LidarfxError(f"unknown conductor {spec!r}; known: {', '.join(CONDUCTORS)} "
                               f"(or a spec 'mass=…,area=…,diameter=…,modulus=…,alpha=…')")
        return CONDUCTORS[name]
    values: dict[str, Any] = {}
    for key, text in _items(spec, "conductor spec"):
        if key not in (*_SPEC_KEYS, "rated_strength", "name"):
            raise LidarfxError(f"unknown conductor spec key {key!r}; known: "
                               f"{', '.join((*_SPEC_KEYS, 'rated_strength', 'name'))}")
        values[key] = text if key == "name" else _number(f"conductor {key}", text)
    missing = [k for k in _SPEC_KEYS if k not in values]
    if missing:
        raise LidarfxError(f"conductor spec lacks {', '.join(missing)} (needs {', '.join(_SPEC_KEYS)})")
    return Conductor(**{"name": "custom", "source": "user spec", **values})


_as_conductor = conductor


@dataclass(frozen=True)
class LoadCase:
    """A weather/load state of the conductor.

    ``temperature`` conductor temperature (°C; None = the survey temperature), ``ice``
    radial ice thickness (mm), ``ice_load`` ice weight (N/m; overrides the weight from the
    thickness, the wind area still uses ``ice``), ``ice_density`` (kg/m³; 900 = glaze ice),
    ``wind`` pressure (Pa) on the projected area of the iced conductor, perpendicular to the
    span; positive = wind from the left of A→B (the conductor swings to the right), negative
    = from the right."""

    temperature: float | None = None
    ice: float = 0.0
    ice_load: float | None = None
    ice_density: float = 900.0
    wind: float = 0.0
    name: str = field(default="", compare=False)

    def __post_init__(self):
        if self.temperature is not None:
            _finite("load case temperature", self.temperature)
        _finite("load case wind", self.wind)
        if not (math.isfinite(self.ice) and self.ice >= 0):
            raise LidarfxError(f"load case ice must be a thickness >= 0 mm, got {self.ice!r}")
        if self.ice_load is not None and not (math.isfinite(self.ice_load) and self.ice_load >= 0):
            raise LidarfxError(f"load case ice_load must be >= 0 N/m, got {self.ice_load!r}")
        _positive("load case ice_density", self.ice_density)


def parse_load_case(text: str | None) -> LoadCase:
    """A :class:`LoadCase` from ``"temp=-5,ice=10,wind=200"``: keys ``temp`` (°C), ``ice``
    (mm), ``ice_load`` (N/m), ``ice_density`` (kg/m³), ``wind`` (Pa), ``wind_speed`` (m/s,
    ``q = ½·1.225·v²``, the sign of v kept), ``name``; an empty text is the survey state."""
    values: dict[str, Any] = {}
    for key, raw in _items(text or "", "load case"):
        key = {"temperature": "temp"}.get(key, key)
        if key not in ("temp", "ice", "ice_load", "ice_density", "wind", "wind_speed", "name"):
            raise LidarfxError(f"unknown load case key {key!r}; known: temp, ice, ice_load, "
                               f"ice_density, wind, wind_speed, name")
        if key in values:
            raise LidarfxError(f"load case key {key!r} given twice")
        values[key] = raw if key == "name" else _number(f"load case {key}", raw)
    if "wind" in values and "wind_speed" in values:
        raise LidarfxError("load case takes wind (Pa) or wind_speed (m/s), not both")
    if "wind_speed" in values:
        v = values.pop("wind_speed")
        values["wind"] = math.copysign(0.5 * AIR_DENSITY * v * v, v)
    if "temp" in values:
        values["temperature"] = values.pop("temp")
    return LoadCase(**{"name": text or "survey", **values})


def unit_loads(cond: Conductor, case: LoadCase) -> tuple[float, float]:
    """``(w_v, w_h)`` (N/m): conductor weight + ice weight ``ρ·g·π·((d+2t)² − d²)/4`` (or
    ``ice_load``), and wind ``pressure·(d + 2t)``."""
    d, t = cond.diameter, case.ice / 1000.0
    ice = case.ice_load if case.ice_load is not None else \
        case.ice_density * G * math.pi * ((d + 2 * t) ** 2 - d * d) / 4.0
    return cond.weight + ice, case.wind * (d + 2 * t)


def _plane(L: float, h: float, phi: float) -> tuple[float, float]:
    """In-plane span X and height difference Y of the chord in the plane swung by phi (rad)."""
    return math.sqrt(L * L + (h * math.sin(phi)) ** 2), h * math.cos(phi)


def conductor_length(a: float, L: float, h: float) -> float:
    """Arc length (m) of the catenary with parameter ``a`` between two points ``L`` apart
    horizontally and ``h`` vertically: ``sqrt(h² + (2a·sinh(L/(2a)))²)``."""
    return math.hypot(h, 2.0 * a * math.sinh(L / (2.0 * a)))


def catenary_sag(a: float, L: float, h: float) -> float:
    """Chord-based sag (m): chord minus curve where the slopes agree."""
    s0, c = catenary_through(0.0, h, L, a)
    s = s0 + a * math.asinh(h / L)
    return h * s / L - (c + a * math.cosh((s - s0) / a))


def mean_tension(H: float, a: float, L: float, h: float) -> float:
    """Tension (N) averaged over the arc length: ``(1/S)∫T ds`` with ``T = H·cosh((s−s0)/a)``."""
    s0, _ = catenary_through(0.0, h, L, a)
    integral = H * (L / 2.0 + a / 4.0 * (math.sinh(2.0 * (L - s0) / a) + math.sinh(2.0 * s0 / a)))
    return integral / conductor_length(a, L, h)


def support_tension(H: float, a: float, L: float, h: float) -> float:
    """Largest tension (N) at the two supports, ``H + w·(z_support − z_vertex)``."""
    s0, _ = catenary_through(0.0, h, L, a)
    return H * max(math.cosh(s0 / a), math.cosh((L - s0) / a))


def _unstretched(H, w, X, Y, theta, EA, alpha, tension) -> float:
    """Length at 0 °C and zero tension: ``S / (1 + α·θ + T/(EA))``."""
    a = H / w
    T = H if tension == "horizontal" else mean_tension(H, a, X, Y)
    return conductor_length(a, X, Y) / (1.0 + alpha * theta + T / EA)


def state_change(H1: float, L: float, h: float, *, w1: float, theta1: float, w2: float,
                 theta2: float, EA: float, alpha: float, swing1_deg: float = 0.0,
                 swing2_deg: float = 0.0, tension: str = "mean") -> float:
    """Tension ``H2`` (N) after a change of state, exact catenary form: the horizontal
    tension, or with wind the component perpendicular to the load in the swung plane.

    The unstretched length is conserved: ``S2/(1 + α·θ2 + T2/(EA)) = S1/(1 + α·θ1 + T1/(EA))``
    with ``S`` the arc length for ``a = H/w`` in each state's load plane (swing angles in
    degrees) and ``T`` the arc-mean tension (``tension="mean"``) or ``H`` (``"horizontal"``).
    Solved with :func:`scipy.optimize.brentq` on a bracket grown from ``H1``."""
    if tension not in ("mean", "horizontal"):
        raise LidarfxError(f"tension must be 'mean' or 'horizontal', got {tension!r}")
    for name, v in (("H1", H1), ("L", L), ("w1", w1), ("w2", w2), ("EA", EA)):
        _positive(name, v)
    for name, v in (("h", h), ("theta1", theta1), ("theta2", theta2), ("alpha", alpha)):
        _finite(name, v)
    for name, v in (("swing1_deg", swing1_deg), ("swing2_deg", swing2_deg)):
        _finite(name, v)
        if abs(v) >= 90.0:
            raise LidarfxError(f"{name} must be within (-90, 90), got {v!r}")
    X1, Y1 = _plane(L, h, math.radians(swing1_deg))
    X2, Y2 = _plane(L, h, math.radians(swing2_deg))
    target = _unstretched(H1, w1, X1, Y1, theta1, EA, alpha, tension)

    def f(H: float) -> float:
        return _unstretched(H, w2, X2, Y2, theta2, EA, alpha, tension) - target

    if f(H1) == 0.0:
        return H1
    lo = hi = H1
    while f(lo) <= 0.0:  # slacker until the conductor is longer than the unstretched one
        lo /= 2.0
        if X2 / (lo / w2) > 100.0:
            raise LidarfxError("change of state has no solution (conductor too long for the span)")
    while f(hi) >= 0.0:
        hi *= 2.0
        if hi > 1e6 * H1:
            raise LidarfxError("change of state has no solution (conductor too short for the span)")
    from scipy.optimize import brentq

    return float(brentq(f, lo, hi, xtol=1e-12 * H1, rtol=4 * np.finfo(float).eps, maxiter=200))


def state_change_parabolic(sigma1: float, g1: float, theta1: float, g2: float, theta2: float,
                           L: float, E: float, alpha: float) -> float:
    """Textbook change of state of a level span (parabola): the real positive root σ2 of
    ``σ2²·(σ2 − σ1 + E·g1²·L²/(24·σ1²) + E·α·(θ2 − θ1)) = E·g2²·L²/24``.

    σ = H/A (N/mm²), g = w/A (N/(m·mm²)), L (m), E (N/mm²), α (1/K); any consistent force
    unit works (the equation is homogeneous in force)."""
    for name, v in (("sigma1", sigma1), ("g1", g1), ("g2", g2), ("L", L), ("E", E)):
        _positive(name, v)
    B = -sigma1 + E * g1 * g1 * L * L / (24.0 * sigma1 * sigma1) + E * alpha * (theta2 - theta1)
    D = E * g2 * g2 * L * L / 24.0
    hi = max(0.0, -B) + D ** (1.0 / 3.0) + 1.0  # p(hi) > 0, p(0) = −D < 0: one positive root
    from scipy.optimize import brentq

    return float(brentq(lambda s: s * s * (s + B) - D, 0.0, hi, xtol=1e-14 * hi, maxiter=200))


@dataclass(frozen=True)
class SpanState:
    """A span in the survey state (1) and under a load case (2); see :func:`predict_span`.

    Forces in N, lengths in m, angles in degrees.  ``a2``, ``sag2`` and ``S2`` are in the
    loaded plane (through the chord, containing the load at ``swing_deg`` from the
    vertical); ``vertical_sag2 = sag2·cos φ`` and
    ``lateral_displacement = sag2·sin φ`` (positive = right of A→B) are its components at
    the sag point.  ``T*_max`` = tension at the more loaded support."""

    conductor: str
    load_case: LoadCase
    L: float
    h: float
    temperature1: float
    temperature2: float
    w1: float
    w_vertical: float
    w_horizontal: float
    w2: float
    swing_deg: float
    H1: float
    H2: float
    a1: float
    a2: float
    sag1: float
    sag2: float
    vertical_sag2: float
    lateral_displacement: float
    S1: float
    S2: float
    T1_max: float
    T2_max: float
    span_in_plane: float
    height_in_plane: float
    rated_strength: float | None
    utilisation: float | None
    exceeds_rated_strength: bool

    def curve(self, A: Any, B: Any, step: float = 0.5) -> np.ndarray:
        """The loaded curve through world points A and B, see :func:`loaded_curve`."""
        return loaded_curve(A, B, self.a2, self.swing_deg, step)


def predict_span(a: float, L: float, h: float, conductor: Any, load_case: Any = None,
                 survey_temperature: float = 10.0, *, tension: str = "mean") -> SpanState:
    """Predict the span's catenary under ``load_case`` (a :class:`LoadCase`, a text for
    :func:`parse_load_case`, or None = survey state) from its survey state (``a``, ``L``,
    ``h``, ``survey_temperature`` °C, bare conductor, no wind); ``conductor`` is anything
    :func:`conductor` takes.

    Warns (:class:`~lidarfx.errors.LidarfxWarning`) when the support tension exceeds the
    conductor's rated strength."""
    _positive("a", a)
    _positive("L", L)
    _finite("h", h)
    _finite("survey_temperature", survey_temperature)
    cond = _as_conductor(conductor)
    case = load_case if isinstance(load_case, LoadCase) else parse_load_case(load_case)
    theta2 = survey_temperature if case.temperature is None else case.temperature
    w1 = cond.weight
    wv, wh = unit_loads(cond, case)
    w2, phi = math.hypot(wv, wh), math.atan2(wh, wv)
    H1 = a * w1
    H2 = state_change(H1, L, h, w1=w1, theta1=survey_temperature, w2=w2, theta2=theta2,
                      EA=cond.axial_stiffness, alpha=cond.alpha, swing2_deg=math.degrees(phi),
                      tension=tension)
    a2 = H2 / w2
    X, Y = _plane(L, h, phi)
    sag2 = catenary_sag(a2, X, Y)
    T2 = support_tension(H2, a2, X, Y)
    rated = None if cond.rated_strength is None else cond.rated_strength * 1000.0
    over = rated is not None and T2 > rated
    if over:
        warnings.warn(f"support tension {T2 / 1000:.1f} kN exceeds the rated strength "
                      f"{cond.rated_strength:g} kN of {cond.name}", LidarfxWarning, stacklevel=2)
    return SpanState(
        conductor=cond.name, load_case=case, L=float(L), h=float(h),
        temperature1=float(survey_temperature), temperature2=float(theta2),
        w1=w1, w_vertical=wv, w_horizontal=wh, w2=w2, swing_deg=math.degrees(phi),
        H1=H1, H2=H2, a1=float(a), a2=a2, sag1=catenary_sag(a, L, h), sag2=sag2,
        vertical_sag2=sag2 * math.cos(phi), lateral_displacement=sag2 * math.sin(phi),
        S1=conductor_length(a, L, h), S2=conductor_length(a2, X, Y),
        T1_max=support_tension(H1, a, L, h), T2_max=T2, span_in_plane=X, height_in_plane=Y,
        rated_strength=cond.rated_strength, utilisation=None if rated is None else T2 / rated,
        exceeds_rated_strength=over)


def loaded_curve(A: Any, B: Any, a2: float, swing_deg: float, step: float = 0.5) -> np.ndarray:
    """``(n, 3)`` points of the catenary with parameter ``a2`` through A and B (world
    coordinates, both included) every ``step`` m of horizontal distance from A.

    The curve lies in the plane through AB that contains the load direction, ``swing_deg``
    from the vertical (0 = vertical plane; positive = the conductor displaced to the right
    of A→B, i.e. wind from the left); ``a2`` is measured in that plane (``H2 / w``)."""
    A, B = (np.asarray(p, float).reshape(-1) for p in (A, B))
    if A.shape != (3,) or B.shape != (3,) or not (np.isfinite(A).all() and np.isfinite(B).all()):
        raise LidarfxError("loaded_curve needs A and B as finite 3-D points")
    _positive("a2", a2)
    _positive("step", step)
    if not (math.isfinite(swing_deg) and abs(swing_deg) < 90.0):
        raise LidarfxError(f"swing_deg must be within (-90, 90), got {swing_deg!r}")
    D = B - A
    L = float(math.hypot(D[0], D[1]))
    if L <= 0.0:
        raise LidarfxError("loaded_curve needs A and B at a horizontal distance > 0")
    phi = math.radians(swing_deg)
    u = np.array([D[0] / L, D[1] / L, 0.0])
    right = np.array([u[1], -u[0], 0.0])
    up = math.cos(phi) * np.array([0.0, 0.0, 1.0]) - math.sin(phi) * right
    X, Y = _plane(L, float(D[2]), phi)
    ex = (D - Y * up) / X
    n = math.floor(L / step * (1.0 + 1e-12))
    s = step * np.arange(n + 1, dtype=float)
    s = np.append(s, L) if L - s[-1] > 1e-9 * L else np.concatenate([s[:-1], [L]])
    x = s * X / L
    x0, c = catenary_through(0.0, Y, X, a2)
    y = c + a2 * np.cosh((x - x0) / a2)
    return A + x[:, None] * ex + y[:, None] * up

