"""End to end in a browser: an iso-intensity curve (the paper's Fig. 1b method) measured on the Lab tab.

``vibsynth serve`` serves the studio; headless Chromium opens the Lab tab, an experimenter sets
up intensity sessions on the generated sines, and scripted participants with a known U-shaped
iso-intensity curve (Verrillo-like: most sensitive near 250 Hz, +20 dB at 10 Hz, +10 dB at
1000 Hz) match every sine to the 250 Hz reference sine with the page's gain slider
(``lab-answer``), through the ``data-testid``s only. A participant "feels" the frequency: the
script finds it in the stimulus that plays (the FFT peak of the session's WAV), never from a
name, and answers the curve's drive with a seeded personal offset (SD 0.5 dB) and per-trial noise
(SD 1 dB); five participants, as the paper's Fig. 1b.
The recovered curve (``vibsynth lab analyze --format csv`` and the page's results) is within
+-2 dB of the known one at every frequency.

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_lab_iso_e2e.py -q``.
"""

from __future__ import annotations

import csv
import io
import json
import math

import numpy as np
import pytest

from tests.e2e.studioutil import by, chromium_or_skip, require_browser, start_serve, visible, wait
from tests.e2e.test_lab_e2e import (
    back_to_set_up,
    next_trial,
    progress,
    read_rows,
    set_range,
    set_up,
    shot,
    start,
    vibsynth,
)

#: Runs on the unit tests' workers (tests/e2e/conftest.py): serve on the null output, a browser page; no time measured.
PARALLEL_SAFE = True

pytestmark = [pytest.mark.e2e]

CONFIG = """bank:
  levels: 9
  loop_seconds: 1
lab:
  folder: {root}
"""

#: The known curve: drive for the intensity of the 250 Hz reference, dB re its drive (log-f interpolated).
U_CURVE = ((10, 20.0), (20, 14.0), (40, 8.0), (80, 3.0), (160, 0.5), (250, 0.0), (400, 2.0), (630, 5.5), (1000, 10.0))
TOLERANCE_DB = 2.0


def true_curve_db(freq_hz: float) -> float:
    f, db = np.array(U_CURVE).T
    return float(np.interp(math.log(freq_hz), np.log(f), db))


def felt_frequency(samples: np.ndarray, fs: float) -> float:
    """What the fingers tell: the frequency of the sine that plays (FFT peak, parabolic interpolation)."""
    window = np.hanning(samples.size)
    spectrum = np.abs(np.fft.rfft(samples * window, n=8 * samples.size))
    k = int(np.argmax(spectrum[1:-1])) + 1
    a, b, c = np.log(spectrum[k - 1 : k + 2] + 1e-300)
    shift = 0.5 * (a - c) / (a - 2 * b + c)
    return float((k + shift) * fs / (8 * samples.size))


@pytest.fixture(scope="module")
def lab(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("lab-iso-e2e")
    root = tmp / "sessions"
    require_browser()
    studio = start_serve(tmp / "serve", channels=1, rate=8000, extra_config=CONFIG.format(root=root))
    try:
        browser = chromium_or_skip(1400, 1000)
        try:
            browser.get(studio.url + "#lab")
            wait(browser, lambda b: b.find_elements(*by("lab-protocol")), "the set-up form")
            yield browser, root, tmp
        finally:
            browser.quit()
    finally:
        studio.stop()


def run_participant(browser, root, tmp, participant: str, seed: int, *, stimuli: str, folder: str = "", reference=""):
    """Set up an intensity session on sines and answer every trial as a participant with the U curve."""
    from vibsynth.formats.recordings import read_recording

    if reference:
        field = browser.find_element(*by("lab-reference"))
        field.clear()
        field.send_keys(reference)
    session, meta = start(
        browser, root, protocol="intensity", participant=participant, seed=seed, folder=folder, stimuli=stimuli
    )
    assert meta["set"]["kind"] == "sines"
    gain_min, gain_max = meta["parameters"]["gain_min"], meta["parameters"]["gain_max"]
    ref = read_recording(session / "stimuli" / "reference.wav")
    reference_hz = felt_frequency(ref.samples, ref.fs)
    # every sine at every gain the slider allows stays under the limiter
    ceiling = meta["set"]["limiter_ceiling"]
    for wav in (session / "stimuli").glob("*.wav"):
        assert np.max(np.abs(read_recording(wav).samples)) * gain_max < ceiling
    rng = np.random.default_rng(seed)
    offset = rng.normal(0.0, 0.5)  # this participant's own sensitivity, the same at every frequency
    answered: dict[float, float] = {}
    while not browser.find_element(*by("lab-done")).is_displayed():
        k, n = progress(browser)
        assert visible(browser, "lab-phase").get_attribute("textContent") == "test"
        slider = visible(browser, "lab-answer")
        lo, hi = float(slider.get_attribute("min")), float(slider.get_attribute("max"))
        assert (10**lo, 10**hi) == (pytest.approx(gain_min), pytest.approx(gain_max))
        visible(browser, "lab-play-reference").click()
        visible(browser, "lab-play").click()
        sid = meta["plan"]["test"][k - 1]["stimuli"][0]
        rec = read_recording(session / "stimuli" / f"{sid}.wav")
        f = felt_frequency(rec.samples, rec.fs)
        db = true_curve_db(f) - true_curve_db(reference_hz) + offset + rng.normal(0.0, 1.0)
        gain = float(np.clip(10 ** (db / 20), gain_min, gain_max))
        answered[f] = gain
        set_range(browser, slider, round(math.log10(gain), 3))
        if k == 2 and participant.endswith("1"):
            shot(browser, tmp, "lab-iso-trial")
        next_trial(browser, slider)
    rows = read_rows(session)
    assert len(rows) == n == len(meta["originals"])
    return session, answered


def test_iso_intensity_curve_recovered_in_the_browser(lab):
    browser, root, tmp = lab
    folders = []
    for who, seed in (("iso1", 11), ("iso2", 12), ("iso3", 13), ("iso4", 14), ("iso5", 15)):
        folder, answered = run_participant(browser, root, tmp, who, seed, stimuli="sines")
        assert len(answered) == 10 and min(answered) == pytest.approx(10, abs=0.05)
        folders.append(folder)
        back_to_set_up(browser)
    out = vibsynth("lab", "analyze", *map(str, folders), "--format", "csv")
    rows = list(csv.DictReader(io.StringIO(out)))
    assert [float(r["frequency_hz"]) for r in rows] == sorted(float(r["frequency_hz"]) for r in rows)
    errors = {float(r["frequency_hz"]): float(r["mean_db"]) - true_curve_db(float(r["frequency_hz"])) for r in rows}
    print("recovered - true (dB):", {f: round(e, 2) for f, e in errors.items()})
    assert len(errors) == 10 and all(abs(e) <= TOLERANCE_DB for e in errors.values()), errors
    assert all(r["n"] == "5" and float(r["sd_db"]) < 3.0 for r in rows)
    # the U shape: the bottom is between 160 and 400 Hz, both ends far above it
    mean = {float(r["frequency_hz"]): float(r["mean_db"]) for r in rows}
    bottom = min(mean, key=mean.get)
    assert 160 <= bottom <= 400 and mean[10.0] > 16 and mean[1000.0] > 7

    # the page's results show the same curve
    for box in browser.find_elements("css selector", "input[type=checkbox]"):
        if box.get_attribute("data-folder") in map(str, folders) and not box.is_selected():
            box.click()
    browser.find_element("xpath", "//button[text()='Analyse selected']").click()
    table = wait(browser, lambda b: b.find_elements(*by("lab-iso-table")), "the iso-intensity results")[0]
    assert visible(browser, "lab-iso-plot")
    cells = [
        [td.text for td in tr.find_elements("tag name", "td")] for tr in table.find_elements("css selector", "tbody tr")
    ]
    assert [float(c[1]) for c in cells] == pytest.approx([round(mean[f], 2) for f in sorted(mean)], abs=0.011)
    shot(browser, tmp, "lab-iso-results")
    result = json.loads(vibsynth("lab", "analyze", *map(str, folders), "--format", "json"))
    assert result["reference_hz"] == 250.0 and len(result["participants"]) == 5


def test_own_frequencies_and_reference_in_the_browser(lab):
    browser, root, tmp = lab
    freqs = "10,25,50,100,200,300,500,1000"
    folder, answered = run_participant(
        browser, root, tmp, "iso6", 16, stimuli="sines", folder=f"sines:{freqs}", reference="sine:200"
    )
    assert sorted(round(f) for f in answered) == [int(f) for f in freqs.split(",")]
    meta = json.loads((folder / "session.json").read_text())
    assert meta["set"]["reference_hz"] == 200.0 and meta["set"]["name"] == f"sines:{freqs}"
    out = vibsynth("lab", "analyze", str(folder), "--format", "csv")
    for r in csv.DictReader(io.StringIO(out)):
        f = float(r["frequency_hz"])
        expected = true_curve_db(f) - true_curve_db(200.0)
        assert abs(float(r["mean_db"]) - expected) <= TOLERANCE_DB + 1.0  # one participant: offset + noise
    back_to_set_up(browser)
    # a bad frequency list: one clear message on the page, no session folder
    known = set(root.iterdir())
    browser.find_element(*by("lab-reference")).clear()
    set_up(browser, protocol="intensity", participant="iso7", seed=1, folder="sines:10,20")
    wait(browser, lambda b: "8-12 different frequencies" in b.find_element(*by("lab-error")).text, "the error message")
    assert set(root.iterdir()) == known
    assert visible(browser, "lab-start")  # the set-up stays, not the last session's end


def test_staircase_recovers_the_curve_in_the_browser(lab):
    """Stronger/weaker answers (lab-stronger, lab-weaker) while a 1-up/1-down staircase per sine sets the level."""
    from selenium.webdriver.support.expected_conditions import staleness_of
    from selenium.webdriver.support.ui import Select

    from vibsynth.formats.recordings import read_recording
    from vibsynth.research.lab.session import Session

    browser, root, tmp = lab
    Select(visible(browser, "lab-method")).select_by_value("staircase")
    folder, meta = start(browser, root, protocol="intensity", participant="stair1", seed=21, stimuli="sines")
    assert meta["method"] == "staircase" and len(meta["plan"]["test"]) == 160
    rng = np.random.default_rng(21)
    while not browser.find_element(*by("lab-done")).is_displayed():
        k, n = progress(browser)
        assert n == 160 and not browser.find_element(*by("lab-next")).is_displayed()
        assert not browser.find_elements(*by("lab-answer"))  # no slider: the staircase sets the level
        visible(browser, "lab-play-reference").click()
        visible(browser, "lab-play").click()
        sid = meta["plan"]["test"][k - 1]["stimuli"][0]
        rec = read_recording(folder / "stimuli" / f"{sid}.wav")
        f = felt_frequency(rec.samples, rec.fs)
        with Session.open(folder) as seen:  # what the fingers feel: the drive the staircase plays
            level = seen.track(sid).next_db
        felt = level - true_curve_db(f) + rng.normal(0.0, 0.5)
        button = visible(browser, "lab-stronger" if felt > 0 else "lab-weaker")
        if k == 5:
            shot(browser, tmp, "lab-iso-staircase")
        button.click()
        wait(browser, lambda b: staleness_of(button)(b) or b.find_element(*by("lab-done")).is_displayed(), "next")
    rows = read_rows(folder)
    assert len(rows) == 160 and {r["judgement"] for r in rows} == {"stronger", "weaker"}
    out = vibsynth("lab", "analyze", str(folder), "--format", "csv")
    errors = {
        float(r["frequency_hz"]): float(r["mean_db"]) - true_curve_db(float(r["frequency_hz"]))
        for r in csv.DictReader(io.StringIO(out))
    }
    print("staircase: recovered - true (dB):", {f: round(e, 2) for f, e in errors.items()})
    assert len(errors) == 10 and all(abs(e) <= TOLERANCE_DB for e in errors.values()), errors
    back_to_set_up(browser)
    Select(browser.find_element(*by("lab-method"))).select_by_value("adjustment")


def test_calibrate_tab_shows_the_response_curve_and_band_and_applies_it(lab):
    """The Calibrate tab: a user profile's response, the iso-intensity sessions' curve, the band, apply."""
    import shutil

    import yaml
    from selenium.webdriver.support.ui import Select

    from vibsynth.app.calibrate import profile_band
    from vibsynth.research.lab.iso import iso_curve
    from vibsynth.research.lab.session import Session
    from vibsynth.settings.actuators import shipped_profile_dir

    browser, root, tmp = lab
    folders = sorted(str(p) for p in root.iterdir() if p.name.startswith(("iso1-", "iso2-", "iso3-")))
    assert len(folders) == 3
    # a user profile (the serve's config folder): the shipped HapCoil example as if measured
    user = tmp / "serve" / "xdg-config" / "vibsynth" / "actuators"
    user.mkdir(parents=True, exist_ok=True)
    shutil.copy(shipped_profile_dir() / "hapcoil-example.yaml", user / "my-coil.yaml")
    doc = yaml.safe_load((user / "my-coil.yaml").read_text())
    doc["name"] = "my-coil"
    (user / "my-coil.yaml").write_text(yaml.safe_dump(doc))
    sessions = [Session.open(f) for f in folders]
    curve = iso_curve(sessions, response=doc["response"])
    _, expected = profile_band(doc["response"], curve.freqs_hz, curve.acceleration_db)

    browser.get(browser.current_url.split("#")[0] + "#calibrate")
    browser.refresh()
    select = wait(browser, lambda b: [e for e in b.find_elements(*by("calibrate-profile")) if e.is_displayed()], "tab")[
        0
    ]
    wait(browser, lambda b: "my-coil" in select.text, "the user profile in the list")
    Select(select).select_by_value("my-coil")
    for box in browser.find_elements(*by("calibrate-session")):
        if box.get_attribute("data-folder") in folders:
            box.click()
    visible(browser, "calibrate-show").click()
    band = wait(browser, lambda b: visible(b, "calibrate-band").get_attribute("data-band"), "the band")
    assert [float(v) for v in band.split(",")] == pytest.approx(expected, abs=0.051)
    assert visible(browser, "calibrate-plot").find_elements(*by("calibrate-iso"))
    shot(browser, tmp, "calibrate-tab")
    visible(browser, "calibrate-apply").click()
    wait(browser, lambda b: "now has the band" in visible(b, "calibrate-status").text, "applied")
    # kept: serve's config file (--config) now assigns the profile to the channel, the rest unchanged
    config = tmp / "serve" / "vibsynth.yaml"
    assert f"Kept in {config}" in visible(browser, "calibrate-status").text
    kept = yaml.safe_load(config.read_text())
    assert kept["actuator"]["channel_profiles"] == ["my-coil"] and kept["audio"]["rate"] == 8000
    written = yaml.safe_load((user / "my-coil.yaml").read_text())
    assert written["band_hz"] == pytest.approx(expected, abs=0.051) and written["response"] == doc["response"]
    assert "lab iso-intensity curve" in written["provenance"]["iso_curve"]
    # a shipped profile is not written
    Select(visible(browser, "calibrate-profile")).select_by_value("hapcoil-example")
    visible(browser, "calibrate-apply").click()
    wait(browser, lambda b: "shipped profile" in visible(b, "calibrate-error").text, "the refusal")
    for s in sessions:
        s.close()
