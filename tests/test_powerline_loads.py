"""Conductor mechanics of lidarfx.powerlines.loads: change of state, loads, loaded curve."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from lidarfx.errors import LidarfxError, LidarfxWarning
from lidarfx.powerlines.loads import (
    CONDUCTORS,
    Conductor,
    G,
    LoadCase,
    catenary_sag,
    conductor,
    conductor_length,
    loaded_curve,
    mean_tension,
    parse_load_case,
    predict_span,
    state_change,
    state_change_parabolic,
    unit_loads,
)
from lidarfx.synth.powerline import catenary_through

DRAKE = conductor("drake")


def test_published_example_parabolic_cubic():
    """Problem 15.3 with its printed answer, as posted at
    https://www.bartleby.com/questions-and-answers/15.3-determine-the-erection-sag-and-tension-of-a-transmission-line-at-65c-in-still-air.-the-line-has/056f79c7-91b3-49ab-ba42-34a223b068e1
    (the page does not name the textbook): span 300 m, ACSR area 240 mm², diameter 20 mm,
    1.0 kg/m, ultimate strength 8000 kg, factor of safety 2 (4000 kg at the worst condition),
    alpha "18.44 x 10-5 /°C" as printed, E = 9320 kg/mm², worst condition -5 °C with 1.0 cm
    radial ice (910 kg/m³) and 40 kg/m² wind on the projected area; erection at 65 °C in
    still air.  Printed answer: sag 20.76 m, tension 541.9 kg."""
    A, L = 240.0, 300.0
    ice = 910.0 * math.pi * 0.010 * (0.020 + 0.010)          # kg/m, ρ·π·t·(d + t)
    w_worst = math.hypot(1.0 + ice, 40.0 * (0.020 + 2 * 0.010))  # kg/m, resultant
    sigma2 = state_change_parabolic(4000 * G / A, w_worst * G / A, -5.0, 1.0 * G / A, 65.0,
                                    L, 9320 * G, 18.44e-5)
    tension_kg = sigma2 * A / G
    assert tension_kg == pytest.approx(541.9, abs=0.05)
    assert 1.0 * L**2 / (8 * tension_kg) == pytest.approx(20.76, abs=0.005)
    # the same example with the physically usual 18.44e-6 /K gives a different, tauter answer
    other = state_change_parabolic(4000 * G / A, w_worst * G / A, -5.0, G / A, 65.0, L, 9320 * G,
                                   18.44e-6) * A / G
    assert other == pytest.approx(1532.6, abs=0.5)


def test_parabolic_cubic_roots_satisfy_the_equation():
    s1, g1, g2, L, E, alpha = 80.0, 0.05, 0.034, 350.0, 74000.0, 19e-6
    s2 = state_change_parabolic(s1, g1, -5.0, g2, 60.0, L, E, alpha)
    lhs = s2**2 * (s2 - s1 + E * g1**2 * L**2 / (24 * s1**2) + E * alpha * 65.0)
    assert s2 > 0 and lhs == pytest.approx(E * g2**2 * L**2 / 24, rel=1e-12)
    assert state_change_parabolic(s1, g1, 10.0, g1, 10.0, L, E, alpha) == pytest.approx(s1, rel=1e-12)


def _exact_and_parabolic(a1, L, dT, tension="horizontal"):
    w, H1 = DRAKE.weight, a1 * DRAKE.weight
    H2 = state_change(H1, L, 0.0, w1=w, theta1=10.0, w2=w, theta2=10.0 + dT,
                      EA=DRAKE.axial_stiffness, alpha=DRAKE.alpha, tension=tension)
    Hp = state_change_parabolic(H1 / DRAKE.area, w / DRAKE.area, 10.0, w / DRAKE.area, 10.0 + dT,
                                L, DRAKE.modulus, DRAKE.alpha) * DRAKE.area
    return H1, H2, Hp


@pytest.mark.parametrize("dT", [50.0, -20.0])
def test_exact_matches_parabolic_for_a_shallow_level_span(dT):
    # sag/L = 2.5 %: the tension change of the two forms agrees within 0.2 %
    for tension in ("horizontal", "mean"):
        H1, H2, Hp = _exact_and_parabolic(1500.0, 300.0, dT, tension)
        assert abs(H2 - H1) > 2000.0
        assert (H2 - H1) / (Hp - H1) == pytest.approx(1.0, abs=2e-3)


def test_exact_departs_from_parabolic_for_a_deep_sag_as_first_order_theory_says():
    """a = 150 m on a 300 m level span (sag/L = 27 %).  To first order the thermal strain
    acts on the arc S in the exact form and on L in the parabola, and dS/da differs:
    ΔH_exact/ΔH_parab = (S/L)·(dSp/dH − L/EA)/(dS/dH − S/EA)."""
    a1, L = 150.0, 300.0
    H1, H2, Hp = _exact_and_parabolic(a1, L, 50.0)
    w, EA = DRAKE.weight, DRAKE.axial_stiffness
    S = conductor_length(a1, L, 0.0)
    dS_da = 2 * math.sinh(L / (2 * a1)) - L / a1 * math.cosh(L / (2 * a1))
    dSp_da = -(L**3) / (12 * a1**3)
    predicted = S / L * (dSp_da / w - L / EA) / (dS_da / w - S / EA)
    ratio = (H2 - H1) / (Hp - H1)
    assert ratio > 1.05
    assert ratio == pytest.approx(predicted, abs=2e-3)


def test_exact_form_conserves_the_unstretched_length_and_has_closed_form_limits():
    w, L, h, H1 = DRAKE.weight, 320.0, 25.0, 1200.0 * DRAKE.weight
    EA, alpha = DRAKE.axial_stiffness, DRAKE.alpha
    H2 = state_change(H1, L, h, w1=w, theta1=10.0, w2=1.7 * w, theta2=-5.0, EA=EA, alpha=alpha)

    def unstretched(H, ww, theta):
        a = H / ww
        return conductor_length(a, L, h) / (1 + alpha * theta + mean_tension(H, a, L, h) / EA)

    assert unstretched(H2, 1.7 * w, -5.0) == pytest.approx(unstretched(H1, w, 10.0), rel=1e-13)
    # inextensible: S2/S1 = (1 + α θ2)/(1 + α θ1); a weight change alone keeps a = H/w
    H3 = state_change(H1, L, h, w1=w, theta1=10.0, w2=w, theta2=70.0, EA=1e18, alpha=alpha)
    assert conductor_length(H3 / w, L, h) / conductor_length(H1 / w, L, h) == \
        pytest.approx((1 + 70 * alpha) / (1 + 10 * alpha), rel=1e-12)
    H4 = state_change(H1, L, h, w1=w, theta1=10.0, w2=2.5 * w, theta2=10.0, EA=1e18, alpha=alpha)
    assert H4 == pytest.approx(2.5 * H1, rel=1e-9)


def test_round_trip_and_same_state():
    w, L, h, H1 = DRAKE.weight, 280.0, -18.0, 1300.0 * DRAKE.weight
    kw = {"EA": DRAKE.axial_stiffness, "alpha": DRAKE.alpha}
    wv, wh = unit_loads(DRAKE, LoadCase(ice=12.0, wind=350.0))
    w2, phi = math.hypot(wv, wh), math.degrees(math.atan2(wh, wv))
    H2 = state_change(H1, L, h, w1=w, theta1=10.0, w2=w2, theta2=-5.0, swing2_deg=phi, **kw)
    back = state_change(H2, L, h, w1=w2, theta1=-5.0, w2=w, theta2=10.0, swing1_deg=phi, **kw)
    assert H2 > 1.5 * H1 and back == pytest.approx(H1, rel=1e-10)
    assert state_change(H1, L, h, w1=w, theta1=10.0, w2=w, theta2=10.0, **kw) == H1
    assert predict_span(1300.0, L, h, DRAKE, None).H2 == predict_span(1300.0, L, h, DRAKE, "").H1
    same = predict_span(1300.0, L, h, DRAKE, LoadCase(temperature=15.0), survey_temperature=15.0)
    assert same.H2 == same.H1 and same.a2 == pytest.approx(1300.0, rel=1e-15)
    assert same.sag2 == pytest.approx(same.sag1, rel=1e-12) and same.S2 == pytest.approx(same.S1, rel=1e-15)


def test_temperature_ice_and_wind_trends():
    base = predict_span(1400.0, 350.0, 12.0, "ACSR Drake", "")
    hot = predict_span(1400.0, 350.0, 12.0, "ACSR Drake", "temp=80")
    cold = predict_span(1400.0, 350.0, 12.0, "ACSR Drake", "temp=-20")
    iced = predict_span(1400.0, 350.0, 12.0, "ACSR Drake", "temp=-5,ice=15")
    assert hot.H2 < base.H2 < cold.H2 and hot.sag2 > base.sag2 > cold.sag2
    assert hot.S2 > base.S2 > cold.S2 and hot.temperature2 == 80.0 and base.temperature2 == 10.0
    assert iced.H2 > base.H2 and iced.T2_max > base.T2_max and iced.sag2 > base.sag2
    assert iced.swing_deg == 0.0 and iced.vertical_sag2 == iced.sag2
    assert base.sag1 == pytest.approx(catenary_sag(1400.0, 350.0, 12.0))


def test_unit_loads_ice_ring_and_wind_area():
    d, t = DRAKE.diameter, 0.010
    wv, wh = unit_loads(DRAKE, LoadCase(ice=10.0, wind=300.0))
    assert wv == pytest.approx(1.628 * G + 900 * G * math.pi * ((d + 2 * t) ** 2 - d * d) / 4, rel=1e-12)
    assert wh == pytest.approx(300.0 * (d + 2 * t), rel=1e-12)
    assert unit_loads(DRAKE, LoadCase(ice=10.0, ice_load=15.0)) == pytest.approx((1.628 * G + 15.0, 0.0))
    assert unit_loads(DRAKE, LoadCase(ice=10.0, ice_density=500.0))[0] < wv


def test_wind_swing_and_loaded_plane_sag():
    L, h = 300.0, 30.0
    st = predict_span(1500.0, L, h, DRAKE, "wind=500")
    wv, wh = DRAKE.weight, 500.0 * DRAKE.diameter
    assert st.w_vertical == pytest.approx(wv) and st.w_horizontal == pytest.approx(wh)
    assert st.swing_deg == pytest.approx(math.degrees(math.atan(wh / wv)), rel=1e-12)
    assert st.w2 == pytest.approx(math.hypot(wv, wh)) and st.a2 == pytest.approx(st.H2 / st.w2)
    phi = math.radians(st.swing_deg)
    assert st.span_in_plane == pytest.approx(math.sqrt(L**2 + (h * math.sin(phi)) ** 2))
    assert st.height_in_plane == pytest.approx(h * math.cos(phi))
    assert st.sag2 == pytest.approx(catenary_sag(st.a2, st.span_in_plane, st.height_in_plane))
    assert st.vertical_sag2 == pytest.approx(st.sag2 * math.cos(phi))
    assert st.lateral_displacement == pytest.approx(st.sag2 * math.sin(phi)) and st.lateral_displacement > 0
    assert st.H2 > st.H1 and st.sag2 > st.sag1 and st.vertical_sag2 < st.sag1
    # the 3-D curve shows the same sag: at the sag point the chord is vertical_sag2 above it
    # and the conductor lateral_displacement to the right (A→B runs east, right = south)
    A, B = np.array([100.0, 50.0, 40.0]), np.array([100.0 + L, 50.0, 40.0 + h])
    pts = loaded_curve(A, B, st.a2, st.swing_deg, step=0.01)
    below = A[2] + h * (pts[:, 0] - A[0]) / L - pts[:, 2]
    i = int(np.argmax(below))
    assert below[i] == pytest.approx(st.vertical_sag2, abs=1e-5)
    assert A[1] - pts[i, 1] == pytest.approx(st.lateral_displacement, abs=1e-4)
    # every offset from the chord lies along the resultant load (down-right)
    chord = A + np.outer((pts[:, 0] - A[0]) / L, B - A)
    off = pts - chord
    r = np.array([0.0, -math.sin(phi), -math.cos(phi)])
    assert np.abs(np.cross(off, r)).max() < 1e-9


def test_negative_wind_swings_left():
    st = predict_span(1500.0, 300.0, 0.0, DRAKE, "wind_speed=-25")
    assert st.swing_deg < 0 and st.lateral_displacement < 0
    assert st.load_case.wind == pytest.approx(-0.5 * 1.225 * 25**2)


@pytest.mark.parametrize("h", [40.0, -40.0])
def test_support_tension_at_the_higher_support(h):
    st = predict_span(1500.0, 300.0, h, DRAKE, "temp=-5,ice=10,wind=200")
    X, Y = st.span_in_plane, st.height_in_plane
    # T = H + w·(y − y_vertex) on the whole curve; the vertex height is c + a
    vertex = catenary_through(0.0, Y, X, st.a2)[1] + st.a2
    vertex_to_top = max(0.0, Y) - vertex  # the higher support is A (y = 0) or B (y = Y)
    assert vertex_to_top > 40.0 * math.cos(math.radians(st.swing_deg))
    assert st.T2_max == pytest.approx(st.H2 + st.w2 * vertex_to_top, rel=1e-9)
    vertex1 = catenary_through(0.0, h, 300.0, 1500.0)[1] + 1500.0
    assert st.T1_max == pytest.approx(st.H1 + st.w1 * (max(0.0, h) - vertex1), rel=1e-9)


def test_mean_tension_is_the_arc_average():
    H, a, L, h = 30000.0, 700.0, 400.0, 60.0
    s0, _ = catenary_through(0.0, h, L, a)
    s = np.linspace(0.0, L, 200001)
    T = H * np.cosh((s - s0) / a)  # tension along the curve
    ds = np.cosh((s - s0) / a)  # arc length per horizontal metre
    f = T * ds
    integral = float(np.sum((f[1:] + f[:-1]) / 2 * np.diff(s)))
    assert mean_tension(H, a, L, h) == pytest.approx(integral / conductor_length(a, L, h), rel=1e-9)
    assert conductor_length(a, L, h) == pytest.approx(float(np.sum((ds[1:] + ds[:-1]) / 2 * np.diff(s))), rel=1e-9)


def test_rated_strength_flag():
    st = predict_span(1500.0, 300.0, 40.0, DRAKE, "temp=-5,ice=10,wind=200")
    assert st.utilisation == pytest.approx(st.T2_max / 140100.0) and not st.exceeds_rated_strength
    with pytest.warns(LidarfxWarning, match="exceeds the rated strength"):
        over = predict_span(2500.0, 250.0, 0.0, "hawk", "ice=50,temp=-20")
    assert over.exceeds_rated_strength and over.utilisation > 1.0
    custom = predict_span(2500.0, 250.0, 0.0, "mass=0.976,area=280.8,diameter=0.02179,modulus=77000,"
                          "alpha=18.9e-6", "ice=50,temp=-20")
    assert custom.rated_strength is None and custom.utilisation is None and not custom.exceeds_rated_strength


def test_loaded_curve_through_a_and_b_with_closed_form_sag_and_step():
    A = np.array([1000.0, 2000.0, 55.0])
    bearing = math.radians(30.0)
    L, h, a = 251.3, -14.0, 900.0
    B = A + np.array([L * math.sin(bearing), L * math.cos(bearing), h])
    pts = loaded_curve(A, B, a, 0.0, step=0.5)
    s = np.hypot(*(pts[:, :2] - A[:2]).T)
    assert np.allclose(pts[0], A, atol=1e-9) and np.allclose(pts[-1], B, atol=1e-8)
    assert len(pts) == math.floor(L / 0.5) + 2  # 503 steps of 0.5 m and the end point at 251.3
    assert np.allclose(np.diff(s)[:-1], 0.5, atol=1e-9) and 0 < s[-1] - s[-2] <= 0.5
    # plan: on the straight chord; heights: z = c + a cosh((s − s0)/a) through A and B
    ux = (B - A)[:2] / L
    assert np.abs((pts[:, 0] - A[0]) * ux[1] - (pts[:, 1] - A[1]) * ux[0]).max() < 1e-9
    s0, c = catenary_through(A[2], B[2], L, a)
    assert np.allclose(pts[:, 2], c + a * np.cosh((s - s0) / a), atol=1e-9)
    # lowest point and sag against the closed forms
    fine = loaded_curve(A, B, a, 0.0, step=0.001)
    sf = np.hypot(*(fine[:, :2] - A[:2]).T)
    assert fine[:, 2].min() == pytest.approx(c + a, abs=1e-6)  # vertex inside the span
    assert sf[np.argmin(fine[:, 2])] == pytest.approx(s0, abs=1e-3)
    sag = (A[2] + h * sf / L - fine[:, 2]).max()
    assert sag == pytest.approx(catenary_sag(a, L, h), abs=1e-8)
    assert catenary_sag(a, L, 0.0) == pytest.approx(a * (math.cosh(L / (2 * a)) - 1), rel=1e-12)


def test_loaded_curve_swing_goes_right_and_keeps_the_in_plane_catenary():
    A, B = np.zeros(3), np.array([0.0, 200.0, 0.0])  # A→B runs north, right = east
    pts = loaded_curve(A, B, 800.0, 35.0, step=1.0)
    assert len(pts) == 201 and np.allclose(pts[-1], B, atol=1e-9)
    phi = math.radians(35.0)
    sag = 800.0 * (math.cosh(100.0 / 800.0) - 1.0)
    mid = pts[100]
    assert mid[0] == pytest.approx(sag * math.sin(phi), abs=1e-9) and mid[0] > 0
    assert -mid[2] == pytest.approx(sag * math.cos(phi), abs=1e-9)
    assert np.allclose(loaded_curve(A, B, 800.0, -35.0)[:, 0], -loaded_curve(A, B, 800.0, 35.0)[:, 0])


def test_span_state_curve_matches_loaded_curve():
    st = predict_span(1500.0, 300.0, 20.0, DRAKE, "ice=5,wind=300")
    A, B = np.array([0.0, 0.0, 30.0]), np.array([300.0, 0.0, 50.0])
    assert np.array_equal(st.curve(A, B, 2.0), loaded_curve(A, B, st.a2, st.swing_deg, 2.0))


def test_parse_load_case():
    assert parse_load_case("temp=80") == LoadCase(temperature=80.0)
    assert parse_load_case("ice=10") == LoadCase(ice=10.0)
    assert parse_load_case("ice_load=15") == LoadCase(ice_load=15.0)
    assert parse_load_case("wind=500") == LoadCase(wind=500.0)
    assert parse_load_case("wind_speed=30").wind == pytest.approx(551.25)
    lc = parse_load_case(" temp=-5, ice=10 ,wind=200,name=winter ")
    assert lc == LoadCase(temperature=-5.0, ice=10.0, wind=200.0) and lc.name == "winter"
    assert parse_load_case("") == LoadCase() and parse_load_case(None).temperature is None
    assert parse_load_case("temperature=40,ice_density=600").ice_density == 600.0


@pytest.mark.parametrize(("text", "match"), [
    ("snow=3", "unknown load case key 'snow'"),
    ("temp=hot", "temp must be a number"),
    ("ice=-1", "ice must be a thickness"),
    ("ice=nan", "ice must be finite"),
    ("ice_load=-2", "ice_load must be >= 0"),
    ("ice_density=0", "ice_density must be > 0"),
    ("wind=100,wind_speed=10", "not both"),
    ("temp=1,temp=2", "given twice"),
    ("temp", "not key=value"),
])
def test_parse_load_case_errors(text, match):
    with pytest.raises(LidarfxError, match=match):
        parse_load_case(text)


def test_conductor_names_and_specs():
    assert conductor("drake") is CONDUCTORS["ACSR Drake"] is conductor("ACSR  DRAKE")
    assert conductor("Hawk").name == "ACSR Hawk"
    assert conductor("435/55") is conductor("434-al1/56-st1a") is CONDUCTORS["434-AL1/56-ST1A"]
    assert conductor("265-AL1/35-ST1A") is conductor("Al/St 265/35") is CONDUCTORS["264-AL1/34-ST1A"]
    assert DRAKE.weight == pytest.approx(1.628 * 9.80665) and DRAKE.axial_stiffness == pytest.approx(77000 * 468.6)
    assert all(c.source and c.rated_strength for c in CONDUCTORS.values())
    c = conductor("mass=1.628,area=468.5,diameter=0.02812,modulus=74000,alpha=18.9e-6,rated_strength=140")
    assert c == Conductor("custom", 0.02812, 468.5, 1.628, 74000.0, 18.9e-6, 140.0, "user spec")
    assert conductor(c) is c


@pytest.mark.parametrize(("spec", "match"), [
    ("condor", "unknown conductor 'condor'; known: ACSR Drake, ACSR Hawk"),
    ("mass=1.6,area=468", "lacks diameter, modulus, alpha"),
    ("mass=1.6,area=468,diameter=0.028,modulus=7e4,alpha=2e-5,colour=red", "unknown conductor spec key 'colour'"),
    ("mass=x,area=468,diameter=0.028,modulus=7e4,alpha=2e-5", "conductor mass must be a number"),
    ("mass=-1,area=468,diameter=0.028,modulus=7e4,alpha=2e-5", "conductor mass must be > 0"),
    ("", "name or a spec"),
])
def test_conductor_errors(spec, match):
    with pytest.raises(LidarfxError, match=match):
        conductor(spec)


@pytest.mark.parametrize(("args", "match"), [
    ((0.0, 300.0, 0.0), "a must be > 0"),
    ((-5.0, 300.0, 0.0), "a must be > 0"),
    ((1500.0, 0.0, 0.0), "L must be > 0"),
    ((1500.0, 300.0, float("nan")), "h must be a finite number"),
])
def test_predict_span_rejects_bad_geometry(args, match):
    with pytest.raises(LidarfxError, match=match):
        predict_span(*args, DRAKE, "")


def test_other_bad_input():
    with pytest.raises(LidarfxError, match="tension must be"):
        predict_span(1500.0, 300.0, 0.0, DRAKE, "", tension="max")
    with pytest.raises(LidarfxError, match="swing_deg"):
        loaded_curve([0, 0, 0], [100, 0, 0], 500.0, 95.0)
    with pytest.raises(LidarfxError, match="horizontal distance"):
        loaded_curve([0, 0, 0], [0, 0, 10], 500.0, 0.0)
    with pytest.raises(LidarfxError, match="step must be > 0"):
        loaded_curve([0, 0, 0], [100, 0, 0], 500.0, 0.0, step=0.0)
    with pytest.raises(LidarfxError, match="3-D points"):
        loaded_curve([0, 0], [100, 0, 0], 500.0, 0.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        predict_span(1500.0, 300.0, 0.0, DRAKE, "temp=50")  # no warning below the rated strength
