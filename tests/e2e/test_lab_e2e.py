"""End to end in a browser: the studio's Lab tab runs each of the paper's three protocols.

``vibsynth serve`` (null output) serves the studio; headless Chromium opens the Lab tab and an
experimenter sets a session up, then a scripted participant answers every trial from a known
rule, through the page's ``data-testid``s only (the page never names a stimulus; the script
knows what plays from the session's plan, as the participant's fingers would):

* dissimilarity: rating = |t1 difference| / the largest one, t1 measured on the stimuli's
  source WAVs (6 textures of the Penn Haptic Texture Toolkit, 21 pairs);
* intensity: the gain that brings the stimulus' 80-200 Hz level to the reference's;
* resynthesis: 1 for the hidden reference, less the further a version's t1 is from it.

The CSVs are checked: pairs complete, order random but seeded, the fitted model gives V1 the
largest weight; gains and ratings are the rule's. Screenshots go to the test's folder (and to
``$VIBSYNTH_E2E_SCREENSHOTS`` when set: docs/images/ is filled from there).

Run: ``scripts/with_jack.sh -- .venv/bin/python -m pytest tests/e2e/test_lab_e2e.py -q``.
"""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.e2e.studioutil import ROOT, by, chromium_or_skip, require_browser, start_serve, visible, wait
from tests.research.lab.conftest import HATT_TEXTURES, RATE, hatt_recording

#: Runs on the unit tests' workers (tests/e2e/conftest.py): serve on the null output, a browser page; no time measured.
PARALLEL_SAFE = True

pytestmark = [pytest.mark.e2e, pytest.mark.shared]

CONFIG = """bank:
  levels: 9
  loop_seconds: 1
lab:
  folder: {root}
"""


# ---------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def lab(tmp_path_factory, hatt_psd):
    """The service, the browser on the Lab tab, the sessions folder and 6 HaTT stimuli."""
    from vibsynth.formats.psd import read_psd_table
    from vibsynth.formats.recordings import write_wav

    tmp = tmp_path_factory.mktemp("lab-e2e")
    stimuli = tmp / "hatt"
    stimuli.mkdir()
    table = read_psd_table(hatt_psd)
    rng = np.random.default_rng(17)
    for name in HATT_TEXTURES:
        write_wav(
            stimuli / f"{name}.wav",
            hatt_recording(table.freqs_hz, table.psd[table.labels.index(name)], seconds=1.5, rng=rng),
            RATE,
        )
    root = tmp / "sessions"
    require_browser()
    studio = start_serve(tmp / "serve", channels=1, rate=8000, extra_config=CONFIG.format(root=root))
    try:
        assert {"name": "lab", "title": "Lab", "script": "/ext/lab/tab.js"} in studio.api("/api/state")["extensions"]
        browser = chromium_or_skip(1400, 1000)
        try:
            browser.get(studio.url + "#lab")  # what `vibsynth lab` opens: the studio on its Lab tab
            wait(browser, lambda b: b.find_elements(*by("lab-protocol")), "the set-up form")
            assert b_selected(browser, "tab-lab")
            yield browser, root, stimuli, tmp
        finally:
            browser.quit()
    finally:
        studio.stop()


def vibsynth(*args: object) -> str:
    """Run the vibsynth command line; its standard output."""
    cmd = [sys.executable, "-m", "vibsynth", *map(str, args)]
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=True).stdout


def b_selected(browser, tab_id: str) -> bool:
    return browser.find_element("id", tab_id).get_attribute("aria-selected") == "true"


def shot(browser, tmp: Path, name: str) -> None:
    browser.save_screenshot(str(tmp / f"{name}.png"))
    target = os.environ.get("VIBSYNTH_E2E_SCREENSHOTS")
    if target:
        Path(target).mkdir(parents=True, exist_ok=True)
        shutil.copy(tmp / f"{name}.png", Path(target) / f"{name}.png")


def true_t1(folder: Path) -> dict[str, float]:
    """t1 of each source WAV (its middle second, as the lab cuts it), by stimulus id."""
    from vibsynth.dsp.analysis import analyze
    from vibsynth.formats.basis_file import default_basis
    from vibsynth.formats.recordings import read_recording
    from vibsynth.research.lab.stimuli import stimulus_id

    out = {}
    for f in sorted(folder.glob("*.wav")):
        rec = read_recording(f)
        n = int(rec.fs)
        start = (rec.samples.size - n) // 2
        out[stimulus_id(f.stem)] = analyze(rec.samples[start : start + n], fs=rec.fs, basis=default_basis()).t1
    return out


def set_up(browser, *, protocol, participant, seed, folder="", stimuli=None, familiarisation=None):
    from selenium.webdriver.support.ui import Select

    Select(browser.find_element(*by("lab-protocol"))).select_by_value(protocol)
    if stimuli is not None:
        Select(browser.find_element(*by("lab-stimuli"))).select_by_value(stimuli)
    for testid, value in (("lab-stimuli-folder", folder), ("lab-participant", participant), ("lab-seed", str(seed))):
        field = browser.find_element(*by(testid))
        field.clear()
        field.send_keys(value)
    if familiarisation is not None:
        field = browser.find_element(*by("lab-familiarisation"))
        field.clear()
        field.send_keys(str(familiarisation))
    browser.find_element(*by("lab-start")).click()


def start(browser, root: Path, **set_up_fields) -> tuple[Path, dict]:
    """Set a session up and start it; its folder and session.json once the first trial shows."""
    known = set(root.iterdir()) if root.exists() else set()
    set_up(browser, **set_up_fields)
    wait(browser, lambda b: any(e.is_displayed() for e in b.find_elements(*by("lab-progress"))), "the first trial")
    folder = new_session_folder(root, known)
    return folder, json.loads((folder / "session.json").read_text())


def new_session_folder(root: Path, known: set[Path]) -> Path:
    found = [p for p in root.iterdir() if p.is_dir() and p not in known and (p / "session.json").is_file()]
    assert len(found) == 1, found
    return found[0]


def set_range(browser, element, value: float) -> None:
    browser.execute_script(
        "arguments[0].value = arguments[1];"
        "arguments[0].dispatchEvent(new Event('input', {bubbles: true}));"
        "arguments[0].dispatchEvent(new Event('change', {bubbles: true}));",
        element,
        str(value),
    )


def progress(browser) -> tuple[int, int]:
    k, n = visible(browser, "lab-progress").text.split(" / ")
    return int(k), int(n)


def next_trial(browser, old) -> None:
    """Press Next and wait for the next trial (its controls are new) or the end."""
    from selenium.webdriver.support.expected_conditions import staleness_of

    visible(browser, "lab-next").click()
    wait(browser, lambda b: staleness_of(old)(b) or b.find_element(*by("lab-done")).is_displayed(), "the next trial")


def read_rows(folder: Path) -> list[dict[str, str]]:
    with open(folder / "trials.csv", newline="") as handle:
        return list(csv.DictReader(handle))


def back_to_set_up(browser) -> None:
    from selenium.webdriver.common.by import By

    done = browser.find_element(*by("lab-done"))
    done.find_element(By.XPATH, ".//button[text()='Back to set-up']").click()
    wait(browser, lambda b: b.find_element(*by("lab-start")).is_displayed(), "the set-up form")


def run_dissimilarity(browser, root, stimuli, participant, seed, t1, *, familiarisation, extras=False, tmp=None):
    folder, meta = start(
        browser,
        root,
        protocol="dissimilarity",
        participant=participant,
        seed=seed,
        folder=str(stimuli),
        familiarisation=familiarisation,
    )
    plan = meta["plan"]
    scale = max(abs(a - b) for a in t1.values() for b in t1.values())
    fam_seen = 0
    while not browser.find_element(*by("lab-done")).is_displayed():
        phase = visible(browser, "lab-phase").get_attribute("textContent")
        k, n = progress(browser)
        assert n == 21
        slider = visible(browser, "lab-answer")
        assert visible(browser, "lab-next").get_attribute("disabled") is not None  # the slider must be moved first
        if phase == "familiarisation":
            assert k == 0
            fam_seen += 1
            value = 0.5
            if extras and fam_seen == 1:
                # keyboard steps a person can use: 1 % of the scale per arrow, 10 % with Page Up
                from selenium.webdriver.common.keys import Keys

                slider.send_keys(Keys.ARROW_RIGHT)
                assert float(slider.get_attribute("value")) == pytest.approx(0.51)
                slider.send_keys(Keys.PAGE_UP)
                assert float(slider.get_attribute("value")) == pytest.approx(0.61)
                assert visible(browser, "lab-next").get_attribute("disabled") is None  # a key press is a move
        else:
            a, b = plan["test"][k - 1]["stimuli"]
            value = abs(t1[a] - t1[b]) / scale
            if extras and k == 3:
                visible(browser, "lab-play").click()  # a replay, counted
            if extras and k == 5:
                visible(browser, "lab-pause").click()
                wait(browser, lambda b: visible(b, "lab-resume").is_displayed(), "paused")
                assert visible(browser, "lab-next").get_attribute("disabled") is not None
                if tmp is not None:
                    shot(browser, tmp, "lab-paused")
                visible(browser, "lab-resume").click()
                wait(browser, lambda b: visible(b, "lab-pause").is_displayed(), "resumed")
            if extras and k == 7 and tmp is not None:
                set_range(browser, slider, round(value, 3))
                shot(browser, tmp, "lab-dissimilarity-trial")
        set_range(browser, slider, round(value, 3))
        next_trial(browser, slider)
    assert fam_seen == familiarisation
    assert visible(browser, "lab-done").get_attribute("data-folder") == str(folder)
    return folder


# ---------------------------------------------------------------- the three protocols
def test_dissimilarity_in_the_browser(lab):
    from selenium.webdriver.common.by import By

    from vibsynth.research.lab.orders import dissimilarity_plan

    browser, root, stimuli, tmp = lab
    shot(browser, tmp, "lab-setup")
    # a bad participant id: one line in lab-error, nothing created
    set_up(browser, protocol="dissimilarity", participant="../escape", seed=1, folder=str(stimuli))
    wait(browser, lambda b: "participant id" in b.find_element(*by("lab-error")).text, "the error")
    assert not root.exists() or not list(root.iterdir())
    t1 = true_t1(stimuli)

    first = run_dissimilarity(browser, root, stimuli, "p01", 11, t1, familiarisation=2, extras=True, tmp=tmp)
    rows = read_rows(first)
    assert len(rows) == 21 and [int(r["trial"]) for r in rows] == list(range(1, 22))
    pairs = {tuple(sorted((r["stimulus_a"], r["stimulus_b"]))) for r in rows}
    ids = sorted(t1)
    assert pairs == {(a, b) for i, a in enumerate(ids) for b in ids[i:]}  # every pair, self-pairs included
    assert sum(r["stimulus_a"] == r["stimulus_b"] for r in rows) == 6
    scale = max(abs(a - b) for a in t1.values() for b in t1.values())
    for r in rows:
        assert float(r["rating"]) == pytest.approx(abs(t1[r["stimulus_a"]] - t1[r["stimulus_b"]]) / scale, abs=6e-4)
        assert r["file_a"] == f"stimuli/{r['stimulus_a']}.wav" and r["participant"] == "p01"
    # trial 3 was replayed, trial 5 paused and resumed (it plays again): both felt twice
    assert [r["plays"] for r in rows[:6]] == ["1", "1", "2", "1", "2", "1"] and {r["plays"] for r in rows[6:]} == {"1"}
    # order: what the seed gives (the command line says the same), not sorted, another seed another
    order = [(r["stimulus_a"], r["stimulus_b"]) for r in rows]
    assert order == [tuple(t["stimuli"]) for t in json.loads((first / "session.json").read_text())["plan"]["test"]]
    plan = vibsynth(
        "lab",
        "plan",
        "dissimilarity",
        "--stimuli",
        str(stimuli),
        "--seed",
        "11",
        "--familiarisation",
        "2",
        "--format",
        "csv",
    )
    planned = [r["stimuli"].split(" / ") for r in csv.DictReader(plan.splitlines()) if r["phase"] == "test"]
    assert [list(p) for p in order] == planned
    assert order != sorted(order)
    assert order != list(dissimilarity_plan(ids, seed=12).test[k].stimuli for k in range(21))
    back_to_set_up(browser)

    # a second participant, same seed: the same order
    second = run_dissimilarity(browser, root, stimuli, "p02", 11, t1, familiarisation=0)
    assert [(r["stimulus_a"], r["stimulus_b"]) for r in read_rows(second)] == order
    back_to_set_up(browser)

    # the results of both, from the page: V1 has the largest weight
    for box in browser.find_elements(By.CSS_SELECTOR, ".lab-sessions input[type=checkbox]"):
        if box.get_attribute("data-folder") in (str(first), str(second)):
            box.click()
    browser.find_element(By.XPATH, "//button[text()='Analyse selected']").click()
    table = wait(browser, lambda b: b.find_elements(By.CSS_SELECTOR, ".lab-results table"), "the results", 120)[0]
    weights = [
        float(row.find_elements(By.TAG_NAME, "td")[1].text) for row in table.find_elements(By.CSS_SELECTOR, "tbody tr")
    ]
    assert len(weights) == 8 and int(np.argmax(weights)) == 0 and weights[0] > 0
    assert browser.find_elements(By.CSS_SELECTOR, ".lab-results svg.mds circle")
    browser.execute_script("document.querySelector('.lab-results').scrollIntoView()")
    shot(browser, tmp, "lab-results")
    # and from the command line, across both participants
    out = vibsynth("lab", "analyze", str(first), str(second), "--splits", "20", "--format", "json")
    result = json.loads(out)
    assert int(np.argmax(result["fit"]["weights"])) == 0 and result["fit"]["cv"] == 8
    assert result["participant_r"] == pytest.approx(1.0)


def test_intensity_in_the_browser_with_a_stop_and_a_resume(lab):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    from vibsynth.dsp.intensity import intensity_level_db
    from vibsynth.formats.recordings import read_recording

    browser, root, stimuli, tmp = lab
    folder, meta = start(browser, root, protocol="intensity", participant="p03", seed=5, folder=str(stimuli))

    def level(sid: str) -> float:
        rec = read_recording(folder / "stimuli" / f"{sid}.wav")
        return intensity_level_db(rec.samples, fs=rec.fs)

    reference = level("reference")
    expected: dict[str, float] = {}

    def answer_until(stop_at: int | None) -> None:
        while not browser.find_element(*by("lab-done")).is_displayed():
            k, n = progress(browser)
            if stop_at is not None and k == stop_at:
                return
            assert visible(browser, "lab-phase").get_attribute("textContent") == "test" and n == 6
            sid = meta["plan"]["test"][k - 1]["stimuli"][0]
            slider = visible(browser, "lab-answer")
            start = float(slider.get_attribute("value"))
            # the slider starts at the plan's gain (on its 0.005 grid)
            assert start == pytest.approx(math.log10(meta["plan"]["test"][k - 1]["start_gain"]), abs=0.0026)
            slider.send_keys(Keys.ARROW_RIGHT)  # keyboard operable: one step of 0.005 (log10)
            assert float(slider.get_attribute("value")) == pytest.approx(start + 0.005, abs=1e-6)
            visible(browser, "lab-play-reference").click()
            visible(browser, "lab-play").click()
            gain = float(np.clip(10 ** ((reference - level(sid)) / 20), 0.2, 5.0))
            expected[sid] = gain
            set_range(browser, slider, round(math.log10(gain), 3))
            if k == 2:
                shot(browser, tmp, "lab-intensity-trial")
            next_trial(browser, slider)

    answer_until(3)
    browser.find_element(By.XPATH, "//button[text()='Stop session (experimenter)']").click()
    wait(browser, lambda b: b.find_element(*by("lab-start")).is_displayed(), "the set-up form")
    item = wait(
        browser,
        lambda b: [e for e in b.find_elements(*by("lab-session")) if e.get_attribute("data-folder") == str(folder)],
        "the unfinished session",
    )[0]
    item.click()
    visible(browser, "lab-resume").click()
    wait(browser, lambda b: any(e.is_displayed() for e in b.find_elements(*by("lab-progress"))), "the resumed run")
    assert progress(browser) == (3, 6)
    answer_until(None)
    rows = read_rows(folder)
    assert [int(r["trial"]) for r in rows] == list(range(1, 7))
    assert sorted(r["stimulus"] for r in rows) == sorted(meta["originals"])
    for r in rows:
        assert float(r["gain"]) == pytest.approx(expected[r["stimulus"]], rel=0.01)
        assert r["reference"] == "reference" and int(r["plays"]) >= 2 and r["reference_plays"] == "1"
    out = vibsynth("lab", "analyze", str(folder), "--format", "json")
    result = json.loads(out)
    assert result["r2"] > 0.99 and result["slope"] == pytest.approx(1.0, abs=0.02)
    assert result["level_sd_after"] < 0.1 < result["level_sd_before"]
    back_to_set_up(browser)


def test_resynthesis_in_the_browser(lab):
    from vibsynth.dsp.analysis import analyze
    from vibsynth.formats.basis_file import default_basis
    from vibsynth.formats.recordings import read_recording

    browser, root, stimuli, tmp = lab
    folder, meta = start(browser, root, protocol="resynthesis", participant="p04", seed=8, folder=str(stimuli))

    def t1(sid: str) -> float:
        rec = read_recording(folder / "stimuli" / f"{sid}.wav")
        return analyze(rec.samples, fs=rec.fs, basis=default_basis()).t1

    def rule(original: str, version: str) -> float:
        if version == "O":
            return 1.0
        sid = f"{original}.{version.replace(':', '-')}"
        return round(float(np.clip(1 - abs(t1(sid) - t1(original)) / 60, 0, 0.95)), 3)

    expected = {}
    while not browser.find_element(*by("lab-done")).is_displayed():
        k, n = progress(browser)
        trial = meta["plan"]["test"][k - 1]
        sliders = [e for e in browser.find_elements(*by("lab-answer")) if e.is_displayed()]
        plays = [e for e in browser.find_elements(*by("lab-play")) if e.is_displayed()]
        assert [s.get_attribute("data-slot") for s in sliders] == ["1", "2", "3", "4", "5"]
        assert [p.get_attribute("data-slot") for p in plays] == ["1", "2", "3", "4", "5"]
        shown = browser.find_element("css selector", ".lab-run").text
        assert not any(sid in shown for sid in meta["stimuli"])  # the participant never sees a name
        for slot, (slider, play) in enumerate(zip(sliders, plays), start=1):
            play.click()
            version = trial["slots"][slot - 1]
            expected[(trial["stimuli"][0], version)] = rule(trial["stimuli"][0], version)
            set_range(browser, slider, expected[(trial["stimuli"][0], version)])
        if k == 1:
            shot(browser, tmp, "lab-resynthesis-trial")
        next_trial(browser, sliders[0])
    shot(browser, tmp, "lab-done")
    rows = read_rows(folder)
    assert len(rows) == 6
    for r in rows:
        for version in ("O", "S1", "S1:8", "S2:8", "M"):
            assert float(r[f"rating_{version}"]) == pytest.approx(expected[(r["original"], version)], abs=1e-3)
            assert r[f"plays_{version}"] == "1"
    out = vibsynth("lab", "analyze", str(folder), "--format", "json")
    summary = {row["version"]: row for row in json.loads(out)["summary"]}
    assert summary["O"]["mean"] == 1.0 and summary["O"]["n"] == 6
    assert summary["S1:8"]["mean"] > summary["M"]["mean"]  # the rule: S1:8 keeps t1, M does not
