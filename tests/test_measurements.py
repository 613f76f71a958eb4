"""The measurement file: round trips of any experiment, the paper's five-column CSV, and
every rule a file can break, each reported in one line naming the file and the place."""

from __future__ import annotations

import json
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from conftest import TABLE1, paper_experiment
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from calibrators import measurements
from calibrators.cli import main
from calibrators.estimators import differences as differences_module
from calibrators.estimators.differences import MissingZeroError, differences
from calibrators.estimators.gauss_newton import GaussNewtonCalibrator
from calibrators.estimators.holdout import MAX_FOLDS, folds
from calibrators.estimators.paper_linear import PaperCalibrator
from calibrators.measurements import (
    MAX_FIELD_CHARS,
    MAX_LINE_BYTES,
    MAX_REPETITION,
    Measurement,
    MeasurementFileError,
    Measurements,
    gauge_name,
)
from orthoglide_env.instruments.slots import GaugeSpec, Part
from orthoglide_env.lab.operations import SLOTS
from orthoglide_env.model.design import PROTOTYPE, MachineDesign
from orthoglide_env.model.kinematics import PAPER_POSTURES, paper_posture

OLD_HEADER = "leg,axis,posture,repetition,reading_mm"

labels = st.text(st.characters(categories=("L", "M", "N", "P", "S"), include_characters=" "),
                 min_size=1, max_size=12).filter(
    lambda s: s == s.strip() and s not in PAPER_POSTURES)


@st.composite
def readings(draw: st.DrawFn) -> Measurement:
    """Any reading of any experiment: any gauge place (a bar anywhere, a carriage, the
    platform), a paper posture or one given by rho (labelled or not), any mounting (named
    after its gauge, so that it holds one)."""
    leg = draw(st.integers(0, 2))
    gauge = draw(st.one_of(
        st.builds(GaugeSpec, st.just(leg), st.sampled_from([a for a in range(3) if a != leg]),
                  st.floats(0.05, 0.95)),
        st.sampled_from([s for s in SLOTS if s.part != Part.BAR])))
    if draw(st.booleans()):
        posture, rho = draw(st.sampled_from(PAPER_POSTURES)), None
    else:
        rho = tuple(draw(st.floats(PROTOTYPE.rho_min, PROTOTYPE.rho_max)) for _ in range(3))
        posture = draw(st.one_of(st.just(""), labels))
    mounting = draw(st.one_of(st.just(""), labels.map(lambda s: f"{s} {gauge_name(gauge)}")))
    return Measurement(gauge, posture, draw(st.integers(1, MAX_REPETITION)),
                       draw(st.floats(-100.0, 100.0)), rho, mounting)


def numbers_of(data: Measurements) -> list[str]:
    """Every number of the readings, as repr: equal only if the floats are identical
    (which == is not for -0.0 and 0.0)."""
    return [repr(v) for m in data.items for v in (m.reading, m.gauge.at, *m.rho)]


def refused(path: Path, content: str | bytes, *fragments: str) -> str:
    """Write ``content`` to ``path``, read it: one line naming the file and ``fragments``."""
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    with pytest.raises(MeasurementFileError) as info:
        Measurements.read(path)
    message = str(info.value)
    assert "\n" not in message and message.startswith(str(path)), message
    for fragment in fragments:
        assert fragment in message, message
    return message


def _written(tmp_path: Path, content: str, name: str = "ok.csv") -> Path:
    path = tmp_path / name
    path.write_text(content)
    return path


def csv_file(*rows: str, header: str = OLD_HEADER) -> str:
    return "\n".join([header, *rows]) + "\n"


# Round trips ----------------------------------------------------------------------------


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(readings(), min_size=1, max_size=20))
def test_any_experiment_round_trips_through_the_csv(tmp_path, items) -> None:
    data = Measurements(items)
    path = tmp_path / "m.csv"
    data.write(path)
    again = Measurements.read(path)
    assert again.items == data.items
    assert numbers_of(again) == numbers_of(data)
    assert [m.line for m in again.items] == list(range(2, len(items) + 2))


@settings(max_examples=60, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(readings(), min_size=1, max_size=20), st.floats(0.0, 1e6))
def test_any_experiment_round_trips_through_json(tmp_path, items, seconds) -> None:
    data = Measurements(items, seconds)
    path = tmp_path / "m.json"
    data.write(path)
    again = Measurements.read(path)
    assert again.items == data.items and again.experiment_time_s == seconds
    assert numbers_of(again) == numbers_of(data)


def test_the_csv_header_comes_first_and_each_reading_is_one_row(tmp_path) -> None:
    data = Measurements([Measurement(GaugeSpec(1, 2, 0.25), "probe", 7, -0.125,
                                     (1.5, -2.0, 3.0), "stand 2")])
    path = tmp_path / "m.csv"
    data.to_csv(path)
    assert path.read_text().splitlines() == [
        "mounting,leg,axis,at,posture,rho_x,rho_y,rho_z,repetition,reading_mm",
        "stand 2,y,z,0.25,probe,1.5,-2.0,3.0,7,-0.125",
    ]


def test_the_papers_five_columns_read_as_before(tmp_path) -> None:
    path = tmp_path / "m.csv"
    path.write_text(csv_file("x,y,Zero,1,0.00", "", " x , z , XMax , 2 , -0.31 ", ",,,,"))
    data = Measurements.read(path)
    assert data.items == [Measurement(GaugeSpec(0, 1), "Zero", 1, 0.0),
                          Measurement(GaugeSpec(0, 2), "XMax", 2, -0.31)]
    assert [m.line for m in data.items] == [2, 4]
    assert [m.mounting for m in data.items] == ["x-leg/y@0.5", "x-leg/z@0.5"]
    assert data.items[1].rho == tuple(paper_posture("XMax", PROTOTYPE))


def test_columns_come_in_any_order(tmp_path) -> None:
    path = tmp_path / "m.csv"
    path.write_text(csv_file("x,y,Zero,1,0.1", "y,z,YMin,3,-0.2"))
    first = Measurements.read(path)
    path.write_text(csv_file("0.1,1,Zero,y,x", "-0.2,3,YMin,z,y",
                             header="reading_mm,repetition,posture,axis,leg"))
    assert Measurements.read(path).items == first.items


def test_the_gauge_as_a_name_or_as_leg_axis_at(tmp_path) -> None:
    path = tmp_path / "m.csv"
    path.write_text(csv_file("x-leg/y,Zero,0.1", "x/z@0.3,Zero,0.2",
                             header="gauge,posture,reading_mm"))
    named = Measurements.read(path)
    path.write_text(csv_file("x,y,,Zero,0.1", "x,z,0.3,Zero,0.2",
                             header="leg,axis,at,posture,reading_mm"))
    assert Measurements.read(path).items == named.items
    assert [m.gauge for m in named.items] == [GaugeSpec(0, 1), GaugeSpec(0, 2, 0.3)]


def test_postures_by_name_by_rho_or_both(tmp_path) -> None:
    xmax = paper_posture("XMax", PROTOTYPE)
    path = tmp_path / "m.csv"
    path.write_text(csv_file(
        "x,y,Zero,,,,0.0",  # a paper posture, its rho filled in
        "x,y,,5,-5,0,0.1",  # rho alone: a label is made
        "x,y,probe,1,2,3,0.2",  # a label of one's own with its rho
        f"x,y,XMax,{xmax[0]:.9f},{xmax[1]:.9f},{xmax[2]:.9f},0.3",  # rounded: the exact rho
        header="leg,axis,posture,rho_x,rho_y,rho_z,reading_mm"))
    data = Measurements.read(path)
    assert [m.posture for m in data.items] == ["Zero", "rho(5,-5,0)", "probe", "XMax"]
    assert [m.rho for m in data.items] == [(0.0, 0.0, 0.0), (5.0, -5.0, 0.0),
                                           (1.0, 2.0, 3.0), tuple(xmax)]


def test_a_byte_order_mark_is_accepted(tmp_path) -> None:
    path = tmp_path / "m.csv"
    path.write_bytes(b"\xef\xbb\xbf" + csv_file("x,y,Zero,1,0.1").encode())
    assert Measurements.read(path).items == [Measurement(GaugeSpec(0, 1), "Zero", 1, 0.1)]
    path = tmp_path / "m.json"
    path.write_bytes(b"\xef\xbb\xbf" + b'{"readings": [{"gauge": "x/y", "posture": "Zero", '
                                       b'"reading_mm": 0.1}]}')
    assert Measurements.read(path).items == [Measurement(GaugeSpec(0, 1), "Zero", 1, 0.1)]


def test_json_rho_as_a_list_or_as_three_keys(tmp_path) -> None:
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"experiment_time_s": 30, "readings": [
        {"leg": "z", "axis": "x", "rho": [1, 2, 3], "reading_mm": 0.5, "repetition": 2},
        {"gauge": "z/x", "rho_x": 1, "rho_y": 2, "rho_z": 3, "reading_mm": 0.5,
         "repetition": 2, "posture": None, "mounting": ""},
    ]}))
    data = Measurements.read(path)
    assert data.items[0] == data.items[1] and data.experiment_time_s == 30.0
    assert data.items[0].posture == "rho(1,2,3)" and data.items[0].line is None


# The CSV's rules ------------------------------------------------------------------------


@pytest.mark.parametrize(("header", "fragment"), [
    pytest.param("leg,axis,posture,reading_mm,temperature,Leg",
                 "unknown column 'temperature', 'Leg'", id="unknown-columns"),
    pytest.param("leg,axis,posture,reading_mm,leg", "'leg' appears more than once",
                 id="repeated-column"),
    pytest.param("leg,axis,posture,repetition", "'reading_mm' is required", id="no-reading"),
    pytest.param("gauge,leg,axis,posture,reading_mm", "not both", id="gauge-twice"),
    pytest.param("leg,posture,reading_mm", "the gauge is missing", id="no-gauge"),
    pytest.param("leg,axis,repetition,reading_mm", "the posture is missing", id="no-posture"),
    pytest.param("leg,axis,rho_x,rho_y,reading_mm", "all of rho_x, rho_y and rho_z",
                 id="part-of-rho"),
])
def test_header_rules(tmp_path, header: str, fragment: str) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,0.1", header=header), ":1: header: ",
            fragment)


def test_each_row_has_the_headers_columns(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,1,0.1", "x,y,XMax,1"),
            ":3: expected 5 columns as in the header, got 4")


@pytest.mark.parametrize("value", ["nan", "inf", "-Infinity", "1e999"])
def test_non_finite_numbers_are_refused(tmp_path, value: str) -> None:
    refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,1,{value}"),
            ":2: column 5 (reading_mm): must be finite")
    refused(tmp_path / "m.csv", csv_file(f"x,y,{value},0,0,0.1",
                                         header="leg,axis,rho_x,rho_y,rho_z,reading_mm"),
            ":2: column 3 (rho_x): must be finite")


def test_text_where_a_number_belongs(tmp_path) -> None:
    for value in ("abc", "0x10", "1_000", "١"):
        refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,1,{value}"),
                ":2: column 5 (reading_mm): must be a number")


def test_readings_beyond_100_mm_are_refused(tmp_path) -> None:
    assert Measurements.read(_written(tmp_path, csv_file("x,y,XMax,1,-100"))).items
    refused(tmp_path / "m.csv", csv_file("x,y,XMax,1,100.5"),
            ":2: column 5 (reading_mm): must lie in [-100, 100] mm (a dial gauge's travel")


def test_rho_outside_the_control_limits_is_refused(tmp_path) -> None:
    header = "leg,axis,rho_x,rho_y,rho_z,reading_mm"
    row = f"x,y,{PROTOTYPE.rho_max},{PROTOTYPE.rho_min},0,0.1"
    assert Measurements.read(_written(tmp_path, csv_file(row, header=header))).items
    refused(tmp_path / "m.csv", csv_file("x,y,0,0,60.001,0.1", header=header),
            ":2: column 5 (rho_z): must lie in [-100, 60] mm (the control limits)")


def test_the_gauges_place_along_its_leg(tmp_path) -> None:
    header = "leg,axis,at,posture,reading_mm"
    refused(tmp_path / "m.csv", csv_file("x,y,0.97,Zero,0.1", header=header),
            ":2: column 3 (at): gauge position 'at' must lie in [0.05, 0.95]")
    refused(tmp_path / "m.csv", csv_file("x,x,0.5,Zero,0.1", header=header),
            ":2: column 2 (axis): must be one of the two axes normal to the x leg")
    refused(tmp_path / "m.csv", csv_file("q,y,0.5,Zero,0.1", header=header),
            ":2: column 1 (leg): must be one of x, y, z")
    refused(tmp_path / "m.csv", csv_file("x/y@0.99,Zero,0.1", header="gauge,posture,reading_mm"),
            ":2: column 1 (gauge): must name a gauge like")


def test_carriage_and_platform_gauges_are_named_in_the_leg_column(tmp_path) -> None:
    """A carriage is its leg's name with ``-carriage``, the platform ``platform``; neither
    has a place along a leg, and a carriage measures across its drive."""
    data = Measurements([Measurement(GaugeSpec.carriage(1, 2), "Zero", 1, 0.0),
                         Measurement(GaugeSpec.platform(0), "probe", 1, -0.25, (1.0, 0.0, 0.0))])
    path = tmp_path / "m.csv"
    data.to_csv(path)
    assert path.read_text().splitlines()[1:] == [
        "y-carriage/z,y-carriage,z,,Zero,0.0,0.0,0.0,1,0.0",
        "platform/x,platform,x,,probe,1.0,0.0,0.0,1,-0.25",
    ]
    assert Measurements.read(path).items == data.items
    named = _written(tmp_path, csv_file(
        "y-carriage/z,Zero,0,0,0,0.0", "platform/x,probe,1,0,0,-0.25",
        header="gauge,posture,rho_x,rho_y,rho_z,reading_mm"))
    assert [m.gauge for m in Measurements.read(named).items] == [m.gauge for m in data.items]
    header = "leg,axis,at,posture,reading_mm"
    refused(tmp_path / "m.csv", csv_file("x-carriage,y,0.5,Zero,0.1", header=header),
            ":2: column 3 (at): a carriage gauge has one place")
    refused(tmp_path / "m.csv", csv_file("x-carriage,x,,Zero,0.1", header=header),
            ":2: column 2 (axis): must be one of the two axes normal to the x leg")
    refused(tmp_path / "m.csv", csv_file("platform,y,0.5,Zero,0.1", header=header),
            ":2: column 3 (at): a platform gauge has one place per face")
    refused(tmp_path / "m.csv", csv_file("platform,w,,Zero,0.1", header=header),
            ":2: column 2 (axis): must be one of x, y, z")
    refused(tmp_path / "m.csv", csv_file("x-carriage/y@0.5,Zero,0.1",
                                         header="gauge,posture,reading_mm"),
            ":2: column 1 (gauge): must name a gauge like")


def test_huge_integers_give_a_clean_error(tmp_path) -> None:
    digits = "1" * 401
    refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,{digits},0.1"),
            ":2: column 4 (repetition): must be an integer 1..1000000, got '1111")
    refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,1,{digits}"),
            ":2: column 5 (reading_mm): must lie in [-100, 100] mm")
    refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,1,-{digits}.5"),
            ":2: column 5 (reading_mm): must be finite")


@pytest.mark.parametrize("value", ["0", "-1", "1.5", "1e3", str(MAX_REPETITION + 1), "one"])
def test_repetitions_are_small_positive_integers(tmp_path, value: str) -> None:
    refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,{value},0.1"),
            ":2: column 4 (repetition): must ")


def test_the_largest_repetition_and_the_default(tmp_path) -> None:
    path = _written(tmp_path, csv_file(f"x,y,XMax,{MAX_REPETITION},0.1", "x,y,XMax,,0.2"))
    assert [m.repetition for m in Measurements.read(path).items] == [MAX_REPETITION, 1]


def test_fields_longer_than_the_limit(tmp_path) -> None:
    assert MAX_FIELD_CHARS == 1024
    refused(tmp_path / "m.csv", csv_file(f"x,y,{'p' * 1025},1,0.1"),
            ":2: column 3 (posture): longer than 1024 characters")
    refused(tmp_path / "m.csv", csv_file(f"x,y,XMax,1,{'0' * 1024}1"),
            ":2: column 5 (reading_mm): longer than 1024 characters")


def test_a_field_beyond_the_csv_modules_limit_names_its_line(tmp_path) -> None:
    # 200 lines of 1000 characters inside one quoted field: past the csv module's own
    # limit (131072) before the record ends.
    huge = "\n".join(["p" * 1000] * 200)
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,1,0.1", f'x,y,"{huge}",1,0.1'),
            ":3: not CSV: field larger than field limit")


def test_lines_longer_than_the_limit(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,1,0.1", "x,y,Zero,1," + " " * MAX_LINE_BYTES),
            f":3: longer than {MAX_LINE_BYTES} bytes")


def test_a_quoted_line_break_is_refused(tmp_path) -> None:
    # csv.reader over splitlines() used to join the two lines into one reading silently.
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,1,0.1", 'x,y,"XMax\nXMin",1,0.1'),
            ":3: a quoted field runs on to line 4: a reading takes one line")


def test_labels_are_printable(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,\"pro\tbe\",1,2,3,0.1",
                                         header="leg,axis,posture,rho_x,rho_y,rho_z,reading_mm"),
            ":2: column 3 (posture): must be 1 to 1024 printable characters")


def test_text_that_is_not_utf8_names_its_line(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,1,0.1").encode() + b"x,y,\xff,1,0.1\n",
            ":3: not UTF-8 text (byte 5 of the line)")


def test_rows_beyond_the_limit(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(measurements.fields, "MAX_ROWS", 3)
    assert len(Measurements.read(_written(tmp_path, csv_file(*["x,y,Zero,1,0.1"] * 3)))) == 3
    refused(tmp_path / "m.csv", csv_file(*["x,y,Zero,1,0.1"] * 4), ":5: more than 3 readings")


def test_a_mounting_holds_one_gauge(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("A,x,y,Zero,0.1", "A,x,z,Zero,0.1",
                                         header="mounting,leg,axis,posture,reading_mm"),
            ":3: column 1 (mounting): mounting 'A' holds gauge x-leg/y@0.5 (line 2), not "
            "x-leg/z@0.5")


def test_a_paper_posture_has_its_own_rho(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,XMax,60,0,0,0.1",
                                         header="leg,axis,posture,rho_x,rho_y,rho_z,reading_mm"),
            ":2: column 3 (posture): XMax is the paper posture at rho (60, -5.857")


def test_a_posture_of_ones_own_needs_its_rho(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,XMid,1,0.1"),
            ":2: column 3 (posture): must be a paper posture (Zero, XMax")
    refused(tmp_path / "m.csv", csv_file("x,y,,1,2,3,0.1", "x,y,,,,,0.1",
                                         header="leg,axis,posture,rho_x,rho_y,rho_z,reading_mm"),
            ":3: column 3 (posture): empty: give a paper posture, or the rho")


def test_required_cells_may_not_be_empty(tmp_path) -> None:
    refused(tmp_path / "m.csv", csv_file("x,y,Zero,1,"), ":2: column 5 (reading_mm): empty")
    refused(tmp_path / "m.csv", csv_file(",Zero,0.1", header="gauge,posture,reading_mm"),
            ":2: column 1 (gauge): empty")
    refused(tmp_path / "m.csv", csv_file("x,y,1,,3,0.1",
                                         header="leg,axis,rho_x,rho_y,rho_z,reading_mm"),
            ":2: column 4 (rho_y): empty: give all of rho_x, rho_y, rho_z or none")


def test_files_without_readings(tmp_path) -> None:
    refused(tmp_path / "m.csv", "", "empty: the header line")
    refused(tmp_path / "m.csv", OLD_HEADER + "\n\n", "no readings after the header")
    refused(tmp_path / "m.json", '{"readings": []}', "no readings")


def test_missing_files_and_other_extensions(tmp_path) -> None:
    with pytest.raises(MeasurementFileError, match="not found"):
        Measurements.read(tmp_path / "none.csv")
    with pytest.raises(MeasurementFileError, match=r"ends in \.csv or \.json"):
        Measurements.read(tmp_path / "m.txt")
    with pytest.raises(MeasurementFileError, match=r"ends in \.csv or \.json"):
        Measurements().write(tmp_path / "m.xlsx")


def test_what_cannot_be_read_back_is_not_written(tmp_path) -> None:
    data = Measurements([Measurement(GaugeSpec(0, 1), "Zero", 1, 0.0, mounting="A"),
                         Measurement(GaugeSpec(0, 2), "Zero", 1, 0.0, mounting="A")])
    with pytest.raises(ValueError, match=r"reading 1: mounting: .* one stand, one gauge"):
        data.to_csv(tmp_path / "m.csv")
    assert not (tmp_path / "m.csv").exists()


# The JSON file's rules ------------------------------------------------------------------


def json_file(*readings: str, top: str = "") -> str:
    return '{"readings": [\n' + ",\n".join(readings) + "\n]" + top + "}\n"


GOOD = '{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1}'


@pytest.mark.parametrize(("reading", "fragment"), [
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": true}',
                 "reading_mm: must be a number, got 'True'", id="boolean-reading"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "repetition": true}',
                 "repetition: must be an integer", id="boolean-repetition"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": "0.1"}',
                 "reading_mm: must be a number, got '0.1'", id="numeric-string"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "repetition": "2"}',
                 "repetition: must be an integer", id="numeric-string-repetition"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "reading_mm": 0.2}',
                 "reading_mm: the key appears more than once", id="duplicate-key"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": NaN}',
                 "reading_mm: must be finite", id="nan"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 1e400}',
                 "reading_mm: must be finite", id="overflowing-float"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": ' + "1" * 401 + "}",
                 "reading_mm: must lie in [-100, 100] mm", id="huge-integer-reading"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "repetition": '
                 + "1" * 401 + "}", "repetition: must be an integer 1..1000000",
                 id="huge-integer-repetition"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "repetition": 2.0}',
                 "repetition: must be an integer", id="float-repetition"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "speed": 3}',
                 "unknown key 'speed'", id="unknown-key"),
    pytest.param('{"gauge": "x/y", "rho": [0, 0], "reading_mm": 0.1}',
                 "rho: must be a list of 3 numbers", id="short-rho"),
    pytest.param('{"gauge": "x/y", "rho": [0, 0, 0], "rho_x": 0, "reading_mm": 0.1}',
                 "rho: give rho as a list or as rho_x, rho_y, rho_z, not both", id="rho-twice"),
    pytest.param('{"gauge": "x/y", "rho": [0, 70, 0], "reading_mm": 0.1}',
                 "rho_y: must lie in [-100, 60] mm", id="rho-beyond-limits"),
    pytest.param('{"gauge": "x/y", "posture": 5, "reading_mm": 0.1}',
                 "posture: must be 1 to 1024 printable characters", id="number-as-label"),
    pytest.param('{"gauge": "x/y", "posture": "Zero", "reading_mm": 0.1, "mounting": 0}',
                 "mounting: must be 1 to 1024 printable characters", id="number-as-mounting"),
    pytest.param('["x/y", "Zero", 0.1]', "must be a JSON object", id="not-an-object"),
])
def test_json_reading_rules(tmp_path, reading: str, fragment: str) -> None:
    refused(tmp_path / "m.json", json_file(GOOD, reading), ": reading 1: " + fragment)


@pytest.mark.parametrize(("content", "fragment"), [
    pytest.param(json_file(GOOD, top=', "readings": []'),
                 "the key 'readings' appears more than once", id="duplicate-readings"),
    pytest.param(json_file(GOOD, top=', "operator": "A"'), "unknown key 'operator'",
                 id="unknown-key"),
    pytest.param(json_file(GOOD, top=', "experiment_time_s": -1'),
                 "experiment_time_s: must lie in [0, 1e+09] s", id="negative-time"),
    pytest.param(json_file(GOOD, top=', "experiment_time_s": false'),
                 "experiment_time_s: must be a number", id="boolean-time"),
    pytest.param('[1, 2]', "must be a JSON object with 'readings'", id="not-an-object"),
    pytest.param('{"readings": {"a": 1}}', "'readings' must be a list", id="readings-not-a-list"),
    pytest.param('{"readings": [\n' + GOOD + ",\n]}", ":3:1: not valid JSON", id="syntax"),
    pytest.param('{"readings": [' + "9" * 5000 + "]}", "not valid JSON", id="5000-digits"),
    pytest.param(b'{"readings": [\n' + GOOD.encode() + b',\n"\xff"]}', ":3: not UTF-8 text",
                 id="not-utf8"),
])
def test_json_document_rules(tmp_path, content: str | bytes, fragment: str) -> None:
    refused(tmp_path / "m.json", content, fragment)


def test_json_readings_beyond_the_limits(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(measurements.fields, "MAX_ROWS", 2)
    refused(tmp_path / "m.json", json_file(GOOD, GOOD, GOOD), ": more than 2 readings")
    monkeypatch.setattr(measurements.json_file, "MAX_JSON_BYTES", 100)
    refused(tmp_path / "m.json", json_file(GOOD, GOOD), ": larger than 100 bytes")


# Differences and verification -----------------------------------------------------------


ZERO_LESS = ("gauge x-leg/z@0.5, mounting 'x-leg/z@0.5', has readings but "
             r"none at Zero \(first reading: line 4\)")


def test_a_gauge_without_a_zero_reading_is_named(tmp_path) -> None:
    data = Measurements.read(_written(tmp_path, csv_file(
        "x,y,Zero,1,0.0", "x,y,XMax,1,0.1", "x,z,XMax,1,0.2", "x,z,XMin,1,0.3")))
    with pytest.raises(MissingZeroError, match=ZERO_LESS):
        differences(data)


@pytest.mark.parametrize("params", ["paper6", "extended", "full"])
def test_every_fit_refuses_a_mounting_without_zero(tmp_path, params) -> None:
    """The exact-model fit could take the missing zero as one more unknown and fit on; it
    refuses instead, as the linear fit does, because such a sheet has lost a line."""
    data = Measurements.read(_written(tmp_path, csv_file(
        "x,y,Zero,1,0.0", "x,y,XMax,1,0.1", "x,z,XMax,1,0.2", "x,z,XMin,1,0.3")))
    with pytest.raises(MissingZeroError, match=ZERO_LESS):
        GaussNewtonCalibrator(params=params).fit(data)


def test_each_mounting_has_its_own_zero() -> None:
    """A gauge re-mounted at the same place reads with another zero: its differences are
    those of the first mounting, and uncorrelated with them (separate Zero readings)."""
    gauge = GaugeSpec(0, 1)
    items = []
    for mounting, zero in (("first", 0.0), ("second", 3.25)):
        items += [Measurement(gauge, "Zero", 1, zero + 0.01, mounting=mounting),
                  Measurement(gauge, "XMax", 1, zero + 0.5, mounting=mounting),
                  Measurement(gauge, "Zero", 2, zero - 0.01, mounting=mounting),
                  Measurement(gauge, "XMax", 2, zero + 0.7, mounting=mounting)]
    rows = differences(Measurements(items))
    assert rows.mountings == ("first", "second")
    np.testing.assert_allclose(rows.values, [0.6, 0.6], atol=1e-12)
    np.testing.assert_allclose(rows.cov_unit, np.diag([1.0, 1.0]))  # 1/2 + 1/2 each


def test_more_differences_than_an_estimate_can_weigh(monkeypatch) -> None:
    gauge = GaugeSpec(0, 1)
    items = [Measurement(gauge, "Zero", 1, 0.0)] + [
        Measurement(gauge, "", 1, 0.1, (float(k), 0.0, 0.0)) for k in range(1, 4)]
    assert len(differences(Measurements(items))) == 3
    monkeypatch.setattr(differences_module, "MAX_DIFFERENCES", 2)
    with pytest.raises(ValueError, match=r"3 \(mounting, posture\) pairs: more than the 2"):
        differences(Measurements(items))


@pytest.fixture(scope="module")
def noisy_paper_data() -> Measurements:
    episode, _ = paper_experiment(TABLE1, errors="paper", gauge_sigma=0.02,
                                  gauge_resolution=0.01)
    return episode.measurements


def test_verification_does_not_depend_on_how_repetitions_are_numbered(noisy_paper_data) -> None:
    """The held-out sets are the repetitions that occur, whatever their numbers (a huge
    number once made it build a set of every number up to it)."""
    renumber = {1: 1, 2: 10, 3: 100, 4: 1000, 5: MAX_REPETITION}
    renumbered = Measurements([
        Measurement(m.gauge, m.posture, renumber[m.repetition], m.reading, m.rho)
        for m in noisy_paper_data.items])
    paper = PaperCalibrator(sigma=0.02)
    before = paper.verify_fit(noisy_paper_data, (0, 1, 2, 3, 4, 5))
    assert before is not None and before > 0
    tracemalloc.start()
    try:
        assert paper.verify_fit(renumbered, (0, 1, 2, 3, 4, 5)) == before
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 5_000_000  # a set of the numbers 1..10^6 alone takes ~60 MB


def test_many_repetitions_are_held_out_in_runs() -> None:
    gauge = GaugeSpec(0, 1)
    items = [Measurement(gauge, posture, rep, 0.0)
             for rep in range(1, 26) for posture in ("Zero", "XMax")]
    held_out = folds(Measurements(items))
    assert len(held_out) == MAX_FOLDS
    assert sorted(r for run in held_out for r in run) == list(range(1, 26))
    assert all(max(run) - min(run) == len(run) - 1 for run in held_out)  # consecutive
    assert len(folds(Measurements(items[:8]))) == 4  # few repetitions: one each


# The command line -----------------------------------------------------------------------


def test_fit_reports_a_bad_file_in_one_line(tmp_path, capsys) -> None:
    for name, content, fragment in (
        ("bad.csv", csv_file("x,y,Zero,1,0.1", "x,y,XMax,1,1e999"),
         "bad.csv:3: column 5 (reading_mm): must be finite"),
        ("bad.json", json_file(GOOD, GOOD.replace("0.1", "true")),
         "bad.json: reading 1: reading_mm: must be a number"),
    ):
        path = _written(tmp_path, content, name)
        assert main(["fit", str(path)]) == 2
        captured = capsys.readouterr()
        lines = captured.err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("orthoglide fit: error: "), lines
        assert fragment in lines[0] and "Traceback" not in captured.err
        assert captured.out == ""


def test_fit_reads_json_as_it_reads_csv(tmp_path, capsys, noisy_paper_data) -> None:
    estimates = []
    for name in ("m.csv", "m.json"):
        noisy_paper_data.write(tmp_path / name)
        assert main(["fit", str(tmp_path / name), "--json"]) == 0
        estimates.append(json.loads(capsys.readouterr().out))
    csv_time, json_time = (e.pop("experiment_time_s") for e in estimates)
    # A CSV keeps no experiment time: its last reading's time is the least it took.
    last = max(m.time_s for m in noisy_paper_data.items)
    assert 0 < csv_time == last <= json_time == noisy_paper_data.experiment_time_s
    # A CSV reading knows its line; a JSON one has no line to name.
    lines = [r.pop("line") for r in estimates[0]["residuals"]]
    assert lines == list(range(2, 68))
    assert estimates[0] == estimates[1] and estimates[0]["n_readings"] == 66


def _csv(tmp_path: Path, header: str, *rows: str) -> Path:
    path = tmp_path / "r.csv"
    path.write_text("\n".join([header, *rows]) + "\n")
    return path


SMALL_FILE = Path(__file__).resolve().parents[1] / "examples" / "designs" / "small.json"


def test_readings_are_checked_on_the_design_of_their_experiment(tmp_path) -> None:
    # Wider limits than the prototype's: a reading there is the design's, not a fault.
    wide = MachineDesign.from_dict({"rho_min": -120.0, "rho_max": 80.0})
    path = _csv(tmp_path, "leg,axis,rho_x,rho_y,rho_z,reading_mm", "x,y,70,-110,0,0.1")
    with pytest.raises(MeasurementFileError, match=r"r.csv:2: column 3 \(rho_x\): must lie "
                                                   r"in \[-100, 60\] mm"):
        Measurements.read(path)
    data = Measurements.read(path, wide)
    assert data.design == wide and data.items[0].rho == (70.0, -110.0, 0.0)
    # The design's own limits refuse in the same words, with its numbers.
    beyond = _csv(tmp_path, "leg,axis,rho_x,rho_y,rho_z,reading_mm", "x,y,90,0,0,0.1")
    with pytest.raises(MeasurementFileError, match=r"r.csv:2: column 3 \(rho_x\): must lie "
                                                   r"in \[-120, 80\] mm .*got '90'"):
        Measurements.read(beyond, wide)
    # A JSON file names its design, and what it names is what its readings are checked on.
    data.write(tmp_path / "wide.json")
    assert Measurements.read(tmp_path / "wide.json") == data
    with pytest.raises(MeasurementFileError, match=r"wide.json: the file's design differs "
                                                   r"from the one given \(in rho_min, rho_max"):
        Measurements.read(tmp_path / "wide.json", PROTOTYPE)
    # Whatever cannot be read back on the design is not written.
    with pytest.raises(ValueError, match=r"reading 0: rho_x: must lie in \[-100, 60\]"):
        Measurements(data.items).write(tmp_path / "proto.csv")


def test_paper_postures_are_the_designs(tmp_path) -> None:
    small = MachineDesign.from_file(SMALL_FILE)
    xmax = paper_posture("XMax", small)
    rho = ",".join(repr(float(v)) for v in xmax)
    path = _csv(tmp_path, "leg,axis,posture,rho_x,rho_y,rho_z,reading_mm",
                f"x,y,XMax,{rho},0.1", "x,y,XMin,,,,0.2")
    with pytest.raises(MeasurementFileError, match=r"r.csv:2: column 3 \(posture\): XMax is "
                                                   r"the paper posture at rho"):
        Measurements.read(path)
    data = Measurements.read(path, small)
    assert [m.posture for m in data.items] == ["XMax", "XMin"]
    assert data.items[0].rho == tuple(xmax)
    assert data.items[1].rho == tuple(paper_posture("XMin", small))
    assert data.items[1].rho != tuple(paper_posture("XMin", PROTOTYPE))


def test_fit_recovers_a_small_machine_from_its_saved_readings(tmp_path, capsys) -> None:
    machine = tmp_path / "m.json"
    machine.write_text('{"drho": [0.5, -0.3, 0.2], "dL": [-0.4, 0.6, 0.1]}')
    saved = tmp_path / "r.csv"
    # The paper's six parameters: what 66 noise-free readings determine exactly.
    design = ["--design", str(SMALL_FILE), "--params", "paper6"]
    assert main(["calibrate", "--machine", str(machine), *design, "--backend", "exact",
                 "--conditions", "ideal", "--save-measurements", str(saved), "--json"]) == 0
    truth = json.loads(capsys.readouterr().out)["truth"]
    assert main(["fit", str(saved), *design, "--sigma", "0", "--resolution", "0",
                 "--json"]) == 0
    estimate = json.loads(capsys.readouterr().out)["estimate"]
    for key in ("drho", "dL"):
        np.testing.assert_allclose(estimate[key], truth[key], atol=1e-6)
