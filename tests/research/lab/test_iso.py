"""Iso-intensity sines: the set spec, the levelling headroom, the plan, and the curve from sessions."""

from __future__ import annotations

import csv
import io
from datetime import datetime, timezone

import numpy as np
import pytest

from vibsynth.errors import InputError, ParameterError
from vibsynth.limits import VOICE_GAIN_MAX
from vibsynth.research.lab.build import (
    SINE_GAIN_RANGE,
    SINE_HEADROOM_DB,
    SessionRequest,
    new_session,
    sine_amplitude,
    sine_reference_hz,
)
from vibsynth.research.lab.iso import is_sine_session, iso_curve, response_at
from vibsynth.research.lab.orders import make_plan
from vibsynth.research.lab.records import Answer
from vibsynth.research.lab.stimuli import DEFAULT_SINES_HZ, load_set, parse_set_spec, parse_sines, sine

T0 = datetime(2026, 3, 1, 10, 0, tzinfo=timezone.utc)


def verrillo_like(f: np.ndarray | float) -> np.ndarray:
    """A U-shaped drive curve, dB re 250 Hz: +20 dB at 10 Hz, 0 at 250 Hz, ~+6 dB at 1000 Hz."""
    return 20.0 * (np.log(np.asarray(f) / 250.0) / np.log(10 / 250.0)) ** 2


def sines(fs: float = 4000.0, spec: str = "sines"):
    return load_set(spec, presets=list, fs=fs, seconds=1.0, seed=0, basis=None)  # type: ignore[arg-type]


# ------------------------------------------------------------------ the set
def test_default_sines_are_ten_log_spaced_from_10_to_1000_hz():
    assert len(DEFAULT_SINES_HZ) == 10 and DEFAULT_SINES_HZ[0] == 10 and DEFAULT_SINES_HZ[-1] == 1000
    ratios = np.diff(np.log(DEFAULT_SINES_HZ))
    assert np.ptp(ratios) < 0.01
    spec = parse_set_spec("sines")
    assert spec.kind == "sines" and spec.freqs == DEFAULT_SINES_HZ and spec.text == "sines"


def test_own_frequencies_are_sorted_and_kept():
    assert parse_sines("1000, 20Hz,10,40,80,160,250,500") == (10, 20, 40, 80, 160, 250, 500, 1000)
    assert parse_set_spec("sines:10,20,40,80,160,250,500,1000").text == "sines:10,20,40,80,160,250,500,1000"


@pytest.mark.parametrize(
    "text",
    [
        "10,20",  # too few
        ",".join(str(10 + 10 * k) for k in range(13)),  # too many
        "5,20,40,80,160,250,500,1000",  # below 10 Hz
        "10,20,40,80,160,250,500,2000",  # above 1000 Hz
        "10,20,40,80,160,250,500,500",  # twice
        "10,20,40,80,160,250,500,nan",
        "10,20,40,80,160,250,500,inf",
        "a,b,c,d,e,f,g,h",
        "10,20,40,80,160,250,500," + "1" * 100,
    ],
)
def test_bad_frequency_lists_get_one_message(text):
    with pytest.raises(ParameterError, match="give 8-12 different frequencies in 10-1000 Hz"):
        parse_set_spec("sines:" + text)


def test_a_sine_is_one_line_with_ramped_ends():
    fs = 4000.0
    x = sine(100.0, fs=fs, seconds=1.0, amplitude=0.5)
    assert x.size == 4000 and np.max(np.abs(x)) == pytest.approx(0.5, abs=1e-3)
    assert abs(x[0]) < 1e-9 and abs(x[-1]) < 0.01
    spectrum = np.abs(np.fft.rfft(x))
    assert np.argmax(spectrum) == 100
    assert spectrum[np.abs(np.arange(spectrum.size) - 100) > 50].max() < 0.001 * spectrum.max()
    with pytest.raises(ParameterError, match="sample rate above 2000"):
        sine(1000.0, fs=1500.0, seconds=1.0)


# ------------------------------------------------------------------ levelling and the session
def test_no_sine_reaches_the_limiter_at_any_allowed_gain(tmp_path, basis):
    ceiling = 0.5
    s = new_session(tmp_path, SessionRequest("intensity", "p1", 3), sines(), basis=basis, limiter_ceiling=ceiling)
    p = s.parameters
    assert (p.gain_min, p.gain_max) == SINE_GAIN_RANGE == (1 / VOICE_GAIN_MAX, VOICE_GAIN_MAX)
    peaks = [float(np.max(np.abs(st.samples))) for st in s.stimuli().values()]
    assert len(peaks) == 11  # 10 sines and the reference
    top = max(peaks) * p.gain_max
    assert top < ceiling and 20 * np.log10(ceiling / top) == pytest.approx(SINE_HEADROOM_DB, abs=0.01)
    # one drive level for all: the gain a participant sets is the drive ratio to the reference
    assert np.ptp(peaks) < 1e-3 * max(peaks)
    assert sine_amplitude(16.0, 0.891) * 16.0 < 0.891
    s.close()


def test_the_reference_sine_is_250_hz_or_the_experimenters(tmp_path, basis):
    assert sine_reference_hz("noise") == 250.0 and sine_reference_hz("sine:80") == 80.0
    for bad in ("sine:5", "sine:2000", "sine:x", "cork", "sine:" + "9" * 40):
        with pytest.raises(ParameterError, match="give sine:F with F in 10-1000 Hz"):
            sine_reference_hz(bad)
    s = new_session(tmp_path, SessionRequest("intensity", "p1", 3, reference="sine:80"), sines(), basis=basis)
    ref = s.stimuli()["reference"]
    spectrum = np.abs(np.fft.rfft(ref.samples))
    assert np.argmax(spectrum) * ref.fs / ref.samples.size == pytest.approx(80.0, abs=1.0)
    assert s.meta["set"]["reference_hz"] == 80.0 and s.meta["reference"] == "reference"
    s.close()


def test_sines_are_for_the_intensity_protocol_only(tmp_path, basis):
    with pytest.raises(ParameterError, match="use the intensity protocol"):
        new_session(tmp_path, SessionRequest("dissimilarity", "p1", 3), sines(), basis=basis)
    assert not tmp_path.exists() or list(tmp_path.iterdir()) == []


def test_the_plan_is_seeded_and_randomised():
    ids = sines().ids
    a = make_plan("intensity", ids, seed=4, gain_min=SINE_GAIN_RANGE[0], gain_max=SINE_GAIN_RANGE[1])
    b = make_plan("intensity", ids, seed=4, gain_min=SINE_GAIN_RANGE[0], gain_max=SINE_GAIN_RANGE[1])
    c = make_plan("intensity", ids, seed=5, gain_min=SINE_GAIN_RANGE[0], gain_max=SINE_GAIN_RANGE[1])
    assert a == b and a.test != c.test
    order = [t.stimuli[0] for t in a.test]
    assert sorted(order) == sorted(ids) and order != ids
    # starts inside the middle half of the +-24 dB range (in dB): +-12 dB
    assert all(abs(20 * np.log10(t.start_gain)) <= 12.0 + 1e-6 for t in a.test)


# ------------------------------------------------------------------ the curve
def run_participant(tmp_path, basis, who, seed, offset_db, noise_db):
    rng = np.random.default_rng(seed)
    s = new_session(tmp_path, SessionRequest("intensity", who, seed), sines(), basis=basis)
    while not s.complete:
        f = s.params()[s.next_trial.stimuli[0]]["frequency_hz"]
        db = float(verrillo_like(f)) + offset_db + rng.normal(0.0, noise_db)
        gain = float(np.clip(10 ** (db / 20), *SINE_GAIN_RANGE))
        s.record(Answer(value=gain, plays=2, reference_plays=1), shown_at=T0, answered_at=T0)
    return s


def test_the_curve_is_each_participants_drive_and_their_mean_and_spread(tmp_path, basis):
    offsets = (-1.0, 0.5, 0.5)
    sessions = [run_participant(tmp_path, basis, f"p{k}", 10 + k, o, 0.0) for k, o in enumerate(offsets)]
    assert all(is_sine_session(s) for s in sessions)
    curve = iso_curve(sessions)
    truth = verrillo_like(np.array(DEFAULT_SINES_HZ))
    assert curve.freqs_hz.tolist() == list(DEFAULT_SINES_HZ) and curve.reference_hz == 250.0
    for row, o in zip(curve.voltage_db, offsets):
        assert row == pytest.approx(truth + o, abs=1e-3)
    assert curve.mean_db == pytest.approx(truth, abs=1e-3)
    assert curve.sd_db == pytest.approx(np.full(10, np.std(offsets, ddof=1)), abs=1e-3)
    rows = list(csv.DictReader(io.StringIO(curve.to_csv())))
    assert list(rows[0]) == ["frequency_hz", "mean_db", "sd_db", "n", "db_p0", "db_p1", "db_p2"]
    assert float(rows[0]["frequency_hz"]) == 10 and float(rows[0]["mean_db"]) == pytest.approx(20.0, abs=0.01)
    for s in sessions:
        s.close()


def test_the_curve_in_acceleration_adds_the_response_re_the_reference(tmp_path, basis):
    s = run_participant(tmp_path, basis, "p1", 1, 0.0, 0.0)
    response = [[10.0, -30.0], [65.0, 0.0], [250.0, -6.0], [1000.0, -18.0]]
    curve = iso_curve([s], response=response)
    r = response_at(response, curve.freqs_hz) - (-6.0)
    assert curve.acceleration_db == pytest.approx(curve.mean_db + r, abs=1e-9)
    assert curve.acceleration_db[-1] == pytest.approx(curve.mean_db[-1] - 12.0, abs=1e-9)
    assert np.isnan(curve.sd_db).all()  # one participant: no spread
    with pytest.raises(InputError, match=r"\[\[Hz, dB\], ...\]"):
        iso_curve([s], response=[[10.0, float("nan")], [20.0, 0.0]])
    s.close()


def test_noisy_participants_recover_the_curve_within_2_db(tmp_path, basis):
    rng = np.random.default_rng(7)
    sessions = [run_participant(tmp_path, basis, f"p{k}", 100 + k, rng.normal(0, 0.5), 1.0) for k in range(5)]
    curve = iso_curve(sessions)
    error = curve.mean_db - verrillo_like(curve.freqs_hz)
    assert np.max(np.abs(error)) < 2.0
    for s in sessions:
        s.close()


def test_other_sessions_are_refused(tmp_path, basis):
    from vibsynth.research.lab.stimuli import load_renders

    s = run_participant(tmp_path, basis, "p1", 1, 0.0, 0.0)
    other = new_session(
        tmp_path,
        SessionRequest("intensity", "p2", 1),
        load_renders(3, fs=4000, seconds=1.0, seed=1, basis=basis),
        basis=basis,
    )
    with pytest.raises(InputError, match="not an iso-intensity session"):
        iso_curve([s, other])
    t = new_session(tmp_path, SessionRequest("intensity", "p3", 1, reference="sine:100"), sines(), basis=basis)
    t.record(Answer(value=1.0), shown_at=T0, answered_at=T0)
    with pytest.raises(InputError, match="different reference sines"):
        iso_curve([s, t])
    for x in (s, other, t):
        x.close()


def test_the_figure_has_the_mean_and_the_acceleration(tmp_path, basis):
    pytest.importorskip("matplotlib")
    from vibsynth.research.plots import iso_curve_figure, plot_iso_curve

    sessions = [run_participant(tmp_path, basis, f"p{k}", k, 0.3 * k, 0.0) for k in range(2)]
    curve = iso_curve(sessions, response=[[10.0, -30.0], [1000.0, 0.0]])
    fig = iso_curve_figure(curve)
    ax = fig.axes[0]
    labels = [line.get_label() for line in ax.get_lines()]
    assert "input voltage (mean of 2)" in labels and "acceleration (measured response)" in labels
    mean = next(line for line in ax.get_lines() if line.get_label().startswith("input voltage"))
    assert mean.get_ydata() == pytest.approx(curve.mean_db)
    path = plot_iso_curve(curve, tmp_path / "iso.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for s in sessions:
        s.close()


# ------------------------------------------------------------------ the staircase method
def test_a_staircase_session_finds_the_curve_and_resumes_from_its_csv(tmp_path, basis):
    from vibsynth.research.lab.session import Session

    request = SessionRequest("intensity", "st1", 5, method="staircase", staircase_trials=16)
    s = new_session(tmp_path, request, sines(), basis=basis)
    assert s.total == 160 and s.method == "staircase"
    rng = np.random.default_rng(5)
    while not s.complete:
        sid = s.next_trial.stimuli[0]
        f = s.params()[sid]["frequency_hz"]
        level = 20 * np.log10(s.staircase_gain())
        felt = level - float(verrillo_like(f)) + rng.normal(0, 0.5)
        # the participant's answer; any value it sends is replaced by the staircase's gain
        s.record(Answer(value=1.0, judgement="stronger" if felt > 0 else "weaker"), shown_at=T0, answered_at=T0)
        if s.done == 77:  # a crash: the session resumes where it was, the staircases too
            s.close()
            s = Session.open(s.folder, write=True)
    rows = s.rows
    assert {r["judgement"] for r in rows} == {"stronger", "weaker"}
    first = next(r for r in rows if r["stimulus"] == "sine-10Hz")
    assert float(first["gain"]) == pytest.approx(
        next(t.start_gain for t in s.plan.test if t.stimuli[0] == "sine-10Hz"), rel=1e-5
    )
    curve = iso_curve([s])
    error = curve.mean_db - verrillo_like(curve.freqs_hz)
    assert np.max(np.abs(error)) < 2.0, error
    s.close()
    with pytest.raises(ParameterError, match="answer stronger or weaker"):
        t = new_session(tmp_path, SessionRequest("intensity", "st2", 5, method="staircase"), sines(), basis=basis)
        t.record(Answer(value=1.0), shown_at=T0, answered_at=T0)
    t.close()


def test_the_staircase_is_for_sines_and_known_methods(tmp_path, basis):
    from vibsynth.research.lab.stimuli import load_renders

    renders = load_renders(3, fs=4000, seconds=1.0, seed=1, basis=basis)
    with pytest.raises(ParameterError, match="use a set of sines"):
        new_session(tmp_path, SessionRequest("intensity", "p1", 1, method="staircase"), renders, basis=basis)
    with pytest.raises(ParameterError, match="unknown method 'bisection'"):
        SessionRequest("intensity", "p1", 1, method="bisection")
    with pytest.raises(ParameterError, match="trials per sine must be 6..60"):
        new_session(
            tmp_path, SessionRequest("intensity", "p1", 1, method="staircase", staircase_trials=1), sines(), basis=basis
        )
    assert not tmp_path.exists() or list(tmp_path.iterdir()) == []
