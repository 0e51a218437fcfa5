"""Fuzz the loaders (issue 15): plant files, recordings (CSV and .mat), valve tables.

For every input, generated (hypothesis, derandomised so the suite is reproducible) or
hand-made, the loader either returns a valid result or raises
:class:`~workbench.errors.InputError` whose message names the file; any other
exception (``UnicodeDecodeError``, ``RecursionError``, ``KeyError``, ``IndexError``,
a numpy warning turned error, ...) fails the test, and hypothesis shrinks the input.
A valid result is checked too: a plant file that loads builds a :class:`Plant`, a
recording that loads has finite, strictly increasing ``t`` and the required columns.

Cases per run: see ``N_*`` below (about 1000 generated + 60 hand-made).
"""

from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, event, given, settings, strategies as st
from hypothesis.control import currently_in_test_context

from workbench.errors import InputError
from workbench.identify.valve.table import load_valve_table
from workbench.params import PlantParams
from workbench.recording import load_recording

from conftest import EFFECT_KEYS, plant_dict

ROOT = Path(__file__).resolve().parents[1]
VALVE_TABLE = ROOT / "tests/data/valve/rig25_table.csv"
RECORDING = ROOT / "tests/data/recordings/step_small.csv"

N_PLANT, N_PLANT_BYTES = 150, 150
N_CSV, N_CSV_BYTES, N_MAT, N_OPTIONS = 200, 150, 60, 80
N_VALVE = 120

_FUZZ = settings(derandomize=True, deadline=None, database=None,
                 suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large,
                                        HealthCheck.filter_too_much])


def fuzz(n: int) -> settings:
    """Reproducible settings (derandomised, no example database) with ``n`` examples."""
    return settings(_FUZZ, max_examples=n)


def _note(label: str) -> None:
    """Count outcomes in hypothesis' statistics (``--hypothesis-show-statistics``)."""
    if currently_in_test_context():
        event(label)


def _outcome(load, path: Path, names: tuple[str, ...] = (), **kw):
    """``load(path)``: the result, or the InputError, which must name the file (or one
    of ``names``, the options being fuzzed)."""
    try:
        result = load(path, **kw)
    except InputError as exc:
        _note("refused")
        msg = str(exc)
        assert any(n in msg for n in (str(path),) + names), \
            f"the message names neither the file nor the option: {exc}"
        return exc
    _note("loaded")
    return result


def _in_tmp(name: str, data: bytes, load, **kw):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / name
        path.write_bytes(data)
        return _outcome(load, path, **kw)


# --------------------------------------------------------------------------------------
# Plant files
# --------------------------------------------------------------------------------------
BASE = plant_dict(controller=True)
KEYS = [(s, k) for s, table in BASE.items() if isinstance(table, dict) for k in table]
SECTIONS = ["gas", "supply", "valve", "cylinder", "load", "friction", "lines", "leakage",
            "controller", "title", "Gas", ""]
NAMES = ["temperature", "pressure", "bore", "stroke", "mass", "kind", "segments", "law",
         "affine_phi", "affine_gamma", "deadband", "coulomb", "static", "length", "x", ""]

toml_scalar = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True), st.integers(-10**20, 10**20),
    st.booleans(), st.text(max_size=8), st.sampled_from([0, -1, 1e-300, 1e300, 20, 0.5]))
toml_value = st.recursive(toml_scalar, lambda inner: st.one_of(
    st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(NAMES), inner, max_size=3)),
    max_leaves=6)


@st.composite
def plant_variants(draw):
    """The base plant with 1-3 edits: mostly plausible (a value scaled, an effect
    switched on), sometimes absurd (any TOML value, a key deleted or added)."""
    data = {s: dict(t) if isinstance(t, dict) else t for s, t in BASE.items()}
    for _ in range(draw(st.integers(1, 3))):
        action = draw(st.sampled_from(["scale", "scale", "effect", "effect", "set",
                                       "delete", "add", "section"]))
        section, key = draw(st.sampled_from(KEYS))
        if action in ("scale", "set", "delete") and not isinstance(data.get(section), dict):
            continue                     # an earlier "section" edit replaced the table
        if action == "scale" and isinstance(data[section].get(key), float):
            data[section][key] *= draw(st.floats(0.5, 2.0))
        elif action == "effect":
            for sec, keys in EFFECT_KEYS[draw(st.sampled_from(sorted(EFFECT_KEYS)))].items():
                if isinstance(data.setdefault(sec, {}), dict):   # not replaced by a value
                    data[sec].update(keys)
        elif action == "set":
            data[section][key] = draw(toml_value)
        elif action == "delete":
            data[section].pop(key, None)
        elif action == "add":
            sec = draw(st.sampled_from(SECTIONS))
            if sec and isinstance(data.get(sec, {}), dict):
                data.setdefault(sec, {})[draw(st.sampled_from(NAMES)) or "k"] = \
                    draw(toml_value)
        elif action == "section":
            data[draw(st.sampled_from(SECTIONS)) or "name"] = draw(toml_value)
    return data


def _check_plant(result) -> None:
    if isinstance(result, PlantParams):
        from workbench.plant import Plant
        plant = Plant(result)
        assert all(math.isfinite(v) for v in plant.pvec())


@fuzz(N_PLANT)
@given(plant_variants())
def test_fuzz_plant_file_values(data):
    try:
        text = tomli_w.dumps(data).encode()
    except (TypeError, ValueError):
        return  # not representable as TOML (e.g. a table inside an array of numbers)
    _check_plant(_in_tmp("plant.toml", text, PlantParams.from_toml))


PLANT_TEXT = tomli_w.dumps(BASE).encode()


@st.composite
def byte_mutations(draw, original: bytes):
    data = bytearray(original)
    for _ in range(draw(st.integers(1, 6))):
        if not data:
            break
        i = draw(st.integers(0, len(data) - 1))
        op = draw(st.sampled_from(["flip", "delete", "insert", "cut", "dup"]))
        if op == "flip":
            data[i] = draw(st.integers(0, 255))
        elif op == "delete":
            del data[i:i + draw(st.integers(1, 40))]
        elif op == "insert":
            data[i:i] = draw(st.sampled_from(
                [b"\x00", b"\xff\xfe", b"\xef\xbb\xbf", b"[", b"]", b"=", b"\n", b",", b"#",
                 b'"', b"nan", b"inf", b"-", b"e999", b"\r\n", b";", b"\t", b"1e-9",
                 b"x [mm],", b"[[a]]\n", b"{a={b={}}}"]))
        elif op == "cut":
            del data[i:]
        else:
            data[i:i] = data[max(0, i - 30):i]
    return bytes(data)


@fuzz(N_PLANT_BYTES)
@given(byte_mutations(PLANT_TEXT))
def test_fuzz_plant_file_bytes(data):
    _check_plant(_in_tmp("plant.toml", data, PlantParams.from_toml))


PLANT_CASES = {
    "empty": b"",
    "bom only": b"\xef\xbb\xbf",
    "utf-16": PLANT_TEXT.decode().encode("utf-16"),
    "latin-1 name": PLANT_TEXT.replace(b'name = "', b'name = "\xe9'),
    "nul": b"\x00" * 10,
    "deep tables": b"a = " + b"{b = " * 5000 + b"1" + b"}" * 5000 + b"\n",
    "deep arrays": b"a = " + b"[" * 50000 + b"]" * 50000 + b"\n",
    "array of tables": b"[[gas]]\ntemperature = 293.15\n",
    "title key": b'title = "x"\n' + PLANT_TEXT,
    "dotted keys": PLANT_TEXT + b"\n[friction]\ncoulomb.x = 1\n",
    "crlf": PLANT_TEXT.replace(b"\n", b"\r\n"),
    "celsius": PLANT_TEXT.replace(b"temperature = 293.15", b"temperature = 20"),
    "datetime": PLANT_TEXT.replace(b"temperature = 293.15", b"temperature = 1979-05-27"),
    "huge int": PLANT_TEXT.replace(b"temperature = 293.15", b"temperature = 1" + b"0" * 400),
}


@pytest.mark.parametrize("name", sorted(PLANT_CASES))
def test_hand_made_plant_files(name):
    result = _in_tmp("plant.toml", PLANT_CASES[name], PlantParams.from_toml)
    _check_plant(result)
    if name not in ("crlf",):
        assert isinstance(result, InputError), name


# --------------------------------------------------------------------------------------
# Recordings
# --------------------------------------------------------------------------------------
COLUMNS = ["t", "u", "x", "p_a", "p_b", "r", "p_s", "v", "T", "x [mm]", "t (ms)", "u [V]",
           "p_a [bar]", "junk", "", '"x"', "x [furlong]"]
CELLS = st.one_of(
    st.floats(-1e6, 1e6, allow_nan=False).map(repr),
    st.sampled_from(["", "nan", "inf", "-inf", "1,5", "abc", "1e400", "-0", "0x10", "1_0",
                     "True", " 3 ", '"4"', "#", "1e-320", "٣"]))


#: A plausible value per column (SI), for rows that should mostly load.
PLAUSIBLE_CELL = {"u": st.floats(0.0, 10.0), "x": st.floats(0.0, 0.5),
                  "r": st.floats(0.0, 0.5), "v": st.floats(-2.0, 2.0),
                  "p_a": st.floats(1e5, 6e5), "p_b": st.floats(1e5, 6e5),
                  "p_s": st.floats(5e5, 6e5)}


@st.composite
def csv_texts(draw):
    """A recording CSV: plausible rows with occasional junk, or junk throughout."""
    sep = draw(st.sampled_from([",", ",", ";", "\t", " "]))
    meta = draw(st.lists(st.sampled_from([
        "# sample_time: 0.001", "# sample_time: 0.01", "# sample_time: -1",
        "# units: x=mm", "# units: t=ms", "# units: x=parsec", "# units: q=mm",
        "# units: garbage", "# rig: a", "# plain comment", "#"]), max_size=2))
    names = draw(st.lists(st.sampled_from(COLUMNS), min_size=1, max_size=6))
    if draw(st.integers(0, 3)) > 0:
        names = ["t", "u", "x"] + [n for n in names[:2] if n not in ("t", "u", "x")]
    names = list(dict.fromkeys(names))
    n = draw(st.integers(0, 30))
    structured = draw(st.integers(0, 3)) > 0
    dt = draw(st.sampled_from([1e-3, 1e-3, 1e-2, 1.0, 1e-7]))
    rows = []
    for k in range(n):
        if structured:
            cells = [repr(k * dt) if c.startswith("t") else
                     repr(draw(PLAUSIBLE_CELL.get(c, st.floats(-1e3, 1e3)))) for c in names]
            if draw(st.integers(0, 19)) == 0:
                cells[draw(st.integers(0, len(cells) - 1))] = draw(CELLS)
        else:
            cells = draw(st.lists(CELLS, min_size=len(names) - 1, max_size=len(names) + 1))
        rows.append(sep.join(cells) + draw(st.sampled_from(["", "", "", sep, sep + sep])))
    return "\n".join(meta + [sep.join(names)] + rows) + draw(st.sampled_from(["", "\n"]))


def _check_recording(result) -> None:
    if not isinstance(result, InputError):
        t = np.asarray(result.t)
        assert t.size >= 2 and np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)
        for name in result.required:
            assert name in result.columns
        for name in result.columns:
            assert np.all(np.isfinite(result[name]))


@fuzz(N_CSV)
@given(csv_texts())
def test_fuzz_recording_csv(text):
    _check_recording(_in_tmp("rec.csv", text.encode(), load_recording))


@fuzz(N_CSV_BYTES)
@given(byte_mutations(RECORDING.read_bytes()))
def test_fuzz_recording_bytes(data):
    _check_recording(_in_tmp("rec.csv", data, load_recording))


mat_value = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=5),
    st.lists(st.floats(-1e3, 1e3), min_size=0, max_size=12).map(np.array),
    st.integers(0, 3).map(lambda k: np.arange(5.0 + k) * 1e-3),
    st.just(np.zeros((2, 3))), st.just(np.array([], dtype=float)),
    st.just(np.array([True, False])), st.just(np.array([1 + 2j, 3j])),
    st.just({"a": 1.0}))


@st.composite
def mat_variables(draw):
    """A plausible t, u, x (+ extras), then 0-3 variables replaced by anything."""
    n = draw(st.integers(2, 20))
    t = np.arange(n) * draw(st.sampled_from([1e-3, 1e-2, 1.0]))
    variables = {"t": t, "u": np.full(n, 5.0), "x": np.linspace(0.1, 0.2, n)}
    if draw(st.booleans()):
        variables["p_a"] = np.full(n, 3e5)
    if draw(st.booleans()):
        variables["sample_time"] = float(t[1] - t[0])
    for _ in range(draw(st.integers(0, 3))):
        name = draw(st.sampled_from(["t", "u", "x", "p_a", "sample_time", "r", "note",
                                     "units"]))
        variables[name] = draw(mat_value)
    return variables


@fuzz(N_MAT)
@given(mat_variables())
def test_fuzz_recording_mat(variables):
    import scipy.io
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "rec.mat"
        try:
            scipy.io.savemat(path, variables)
        except Exception:  # noqa: BLE001 - scipy cannot write it: nothing to load
            return
        _check_recording(_outcome(load_recording, path))


@fuzz(N_OPTIONS)
@given(columns=st.one_of(st.none(), st.text(max_size=20), st.sampled_from(
           ["x=x:mm", "t=t:ms", "x=p_a", "u=x,x=u", "x=", "=x", "x=x:parsec", "q=x",
            "x=x:mm,x=x:m", "p_a=p_a:bar_g", "t=t:s:s"])),
       window=st.one_of(st.none(), st.tuples(
           st.one_of(st.none(), st.floats(allow_nan=True)),
           st.one_of(st.none(), st.floats(allow_nan=True)))),
       required=st.one_of(st.none(), st.lists(st.sampled_from(["t", "u", "x", "p_s", "q"]),
                                                max_size=3).map(tuple)))
def test_fuzz_recording_options(columns, window, required):
    kw = dict(columns=columns, window=window, required=required)
    _check_recording(_outcome(load_recording, RECORDING, names=("--columns",), **kw))


RECORDING_CASES = {
    "empty": b"",
    "bom only": b"\xef\xbb\xbf",
    "bom + header": b"\xef\xbb\xbft,u,x\n",
    "utf-16": RECORDING.read_text().encode("utf-16"),
    "nul bytes": b"t,u,x\n0,5,0.2\n\x00\x00\x00\n",
    "cr only": RECORDING.read_bytes().replace(b"\n", b"\r"),
    "crlf": RECORDING.read_bytes().replace(b"\n", b"\r\n"),
    "one long line": b"t,u,x\n" + b"0," * 100000 + b"0\n",
    "header only commas": b",,,\n1,2,3\n",
    "duplicate t": b"t,u,x\n0,5,0.2\n0,5,0.2\n",
    "decreasing t": b"t,u,x\n1,5,0.2\n0,5,0.2\n",
    "quoted": b'"t","u","x"\n"0","5","0.2"\n"0.001","5","0.2"\n',
    "mixed separators": b"t,u;x\n0,5;0.2\n0.001,5;0.2\n",
    "units twice": b"# units: x=mm\nt,u,x [m]\n0,5,0.2\n0.001,5,0.2\n",
    "units wrong kind": b"# units: x=ms\nt,u,x\n0,5,0.2\n0.001,5,0.2\n",
    "units in header unknown": b"t,u,x [parsec]\n0,5,0.2\n0.001,5,0.2\n",
    "x and x [mm]": b"t,u,x,x [mm]\n0,5,0.2,200\n0.001,5,0.2,200\n",
    "denormal step": b"t,u,x\n0,5,0.2\n5e-324,5,0.2\n1e-323,5,0.2\n",
    "huge t": b"t,u,x\n1e308,5,0.2\n1.7e308,5,0.2\n",
    "1e6 s gap": b"t,u,x\n0,5,0.2\n0.001,5,0.2\n1000000,5,0.2\n",
    "sample_time text": b"# sample_time: fast\nt,u,x\n0,5,0.2\n0.001,5,0.2\n",
    "only comments": b"# a\n# b: c\n",
    "numbers as header": b"0,5,0.2\n0.001,5,0.2\n",
    "trailing delimiters": b"t,u,x,\n0,5,0.2,\n0.001,5,0.2,\n",
    "bad trailing": b"t,u,x,\n0,5,0.2,7\n0.001,5,0.2,\n",
}


@pytest.mark.parametrize("name", sorted(RECORDING_CASES))
@pytest.mark.parametrize("suffix", [".csv", ".mat"])
def test_hand_made_recordings(name, suffix):
    _check_recording(_in_tmp("rec" + suffix, RECORDING_CASES[name], load_recording))


# --------------------------------------------------------------------------------------
# Valve tables
# --------------------------------------------------------------------------------------
def _check_table(result) -> None:
    if not isinstance(result, InputError):
        for name in ("u", "p", "q_m"):
            assert np.all(np.isfinite(getattr(result, name)))


@fuzz(N_VALVE)
@given(byte_mutations(VALVE_TABLE.read_bytes()[:4000]))
def test_fuzz_valve_table_bytes(data):
    _check_table(_in_tmp("table.csv", data, load_valve_table))


VALVE_CASES = {
    "empty": b"",
    "bom only": b"\xef\xbb\xbf",
    "latin-1": b"# caf\xe9\nu,p,q_m\n",
    "header only": b"u,p,q_m\n",
    "bar pressures": b"u,p,q_m\n" + b"".join(b"%d,%d,0.001\n" % (u, p)
                                               for u in range(5) for p in range(1, 6)),
    "nan": b"u,p,q_m\n1,2e5,nan\n",
    "directory": None,
    "fifo": None,
}


@pytest.mark.parametrize("name", sorted(VALVE_CASES))
def test_hand_made_valve_tables(name):
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "table.csv"
        if name == "directory":
            path.mkdir()
        elif name == "fifo":
            os.mkfifo(path)
        else:
            path.write_bytes(VALVE_CASES[name])
        result = _outcome(load_valve_table, path)
    assert isinstance(result, InputError), name
