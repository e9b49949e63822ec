"""The session archive (app.session_file): everything round-trips exactly, points are stored
binary, and a damaged or hostile archive is refused with a message naming the problem, before
any document changes."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np
import pytest

from app.session_file import (
    ARCHIVE_FORMAT,
    MANIFEST,
    load_session,
    read_session,
    save_session,
    write_archive,
)
from app.state import Document, Target, with_changes
from nurbs_core.patches.network import build_network


def _cube_network():
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    return build_network(corners, quads, size=5, degree=3)


def _document(points: np.ndarray) -> Document:
    document = Document()
    document.replace_content([Target("scan", points, "/data/scan.ply")], [], [])
    document._apply_settings(with_changes(document.settings, optimizer="sgd", fit_mode="patches"))
    return document


def test_a_session_round_trips_points_network_and_report_exactly(tmp_path):
    points = np.random.default_rng(0).normal(size=(200_000, 3))
    document = _document(points)
    network = _cube_network()
    network = network.with_control_points(network.control_points * 1.5)
    document.set_network(network)
    deviation = np.random.default_rng(1).random(len(points))
    report = {"event": "done", "quality": {"patches": 6, "flipped_fraction": None,
                                           "seam": {"p99": 0.5, "max": 1.25}},
              "warnings": ["seams are not tangent everywhere"], "passes": 7, "elapsed": 3.5,
              "deviation": deviation}
    path = tmp_path / "work.nstudio"
    save_session(document, path, report)
    # binary: the points take their 24 bytes each, not JSON's ~60
    assert path.stat().st_size < 1.1 * points.nbytes + deviation.nbytes + 200_000
    session = read_session(path)
    np.testing.assert_array_equal(session["targets"][0].points, points)
    assert session["targets"][0].path == "/data/scan.ply"
    assert session["settings"] == document.settings
    np.testing.assert_array_equal(session["network"].control_points, network.control_points)
    assert session["network"].closed and session["network"].patch_count == 6
    np.testing.assert_array_equal(session["network_report"]["deviation"], deviation)
    assert session["network_report"]["warnings"] == report["warnings"]
    assert session["network_report"]["quality"]["seam"]["p99"] == 0.5
    other = Document()
    load_session(other, path)
    np.testing.assert_array_equal(other.targets[0].points, points)
    assert other.settings.fit.optimizer == "sgd" and other.settings.fit_mode == "patches"


def test_older_json_sessions_still_open(tmp_path):
    from app.state import JSON_SESSION_FORMAT, Settings

    path = tmp_path / "old.json"
    path.write_text(json.dumps({"format": JSON_SESSION_FORMAT, "settings": Settings().to_json(),
                                "targets": [{"name": "a", "points": [[0, 0, 0], [1, 0, 0]]}],
                                "patches": [], "fitted": None}))
    session = read_session(path)
    assert session["targets"][0].points.shape == (2, 3) and session["network"] is None


def _manifest(**change):
    return {"format": ARCHIVE_FORMAT, "settings": Document().settings.to_json(),
            "targets": [{"name": "a", "path": "", "visible": True, "points": "targets/0"}],
            "patches": [], "fitted": None, "network": None, "network_report": None, **change}


def _settings(**fit):
    settings = Document().settings.to_json()
    settings["fit"].update(fit)
    return settings


def _npy(array: np.ndarray, allow_pickle: bool = False) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array, allow_pickle=allow_pickle)
    return buffer.getvalue()


def _zip(path, members: dict[str, bytes], compression=zipfile.ZIP_STORED):
    with zipfile.ZipFile(path, "w", compression) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


GOOD_POINTS = np.zeros((4, 3))


@pytest.mark.parametrize("members, compression, message", [
    ({MANIFEST: json.dumps(_manifest()), "targets/0.npy": _npy(GOOD_POINTS)},
     zipfile.ZIP_DEFLATED, "compressed"),                        # no bombs: members are stored
    ({MANIFEST: json.dumps(_manifest())}, zipfile.ZIP_STORED, "lacks targets/0.npy"),
    ({MANIFEST: json.dumps(_manifest()),
      "targets/0.npy": _npy(np.array([{"x": 1}], dtype=object), allow_pickle=True)},
     zipfile.ZIP_STORED, "holds object, not numbers"),          # never unpickled
    ({MANIFEST: json.dumps(_manifest()), "targets/0.npy": _npy(GOOD_POINTS)[:-40]},
     zipfile.ZIP_STORED, "more than it holds"),
    ({MANIFEST: json.dumps(_manifest()), "targets/0.npy": _npy(np.zeros((4, 2)))},
     zipfile.ZIP_STORED, r"expected \(N, 3\) coordinates"),
    ({MANIFEST: json.dumps(_manifest()), "targets/0.npy": _npy(np.full((4, 3), np.nan))},
     zipfile.ZIP_STORED, "NaN or infinite"),
    # coordinates a cloud file may not have (the fit's squared distances overflow)
    ({MANIFEST: json.dumps(_manifest()), "targets/0.npy": _npy(np.full((4, 3), 1e200))},
     zipfile.ZIP_STORED, "coordinates reach 1e[+]200"),
    # settings beyond what a fit may claim (10**9 control points hung the window at 2.5 GB)
    ({MANIFEST: json.dumps(_manifest(settings=_settings(control_points_u=10**9))),
      "targets/0.npy": _npy(GOOD_POINTS)}, zipfile.ZIP_STORED,
     "control_points_u must be at most 1000"),
    ({MANIFEST: json.dumps(_manifest(settings=_settings(samples_u=10**6, samples_v=10**6))),
      "targets/0.npy": _npy(GOOD_POINTS)}, zipfile.ZIP_STORED, "more than the 4194304"),
    ({MANIFEST: "{not json", "targets/0.npy": _npy(GOOD_POINTS)}, zipfile.ZIP_STORED,
     "not valid JSON"),
    ({MANIFEST: json.dumps(_manifest(format="nurbs-studio-session-v9"))}, zipfile.ZIP_STORED,
     "not a NURBS Studio session"),
    ({MANIFEST: json.dumps(_manifest(network="network.json")),
      "targets/0.npy": _npy(GOOD_POINTS), "network.json": json.dumps({"format": "x"})},
     zipfile.ZIP_STORED, "not a patch-network document"),
])
def test_damaged_archives_are_refused_before_the_document_changes(tmp_path, members,
                                                                  compression, message):
    path = _zip(tmp_path / "bad.nstudio", members, compression)
    document = _document(np.ones((3, 3)))
    before = (document.targets, document.settings)
    with pytest.raises(ValueError, match=message):
        load_session(document, path)
    assert (document.targets, document.settings) == before


def _fitted_surface(**change):
    from nurbs_core.geometry_arrays import SurfaceArrays

    knots = [0.0] * 4 + [1.0] * 4
    surface = SurfaceArrays(3, 3, np.zeros((4, 4, 3)), np.ones((4, 4)), np.array(knots),
                            np.array(knots))
    return {**surface.to_json(), **change}


def _patch_settings(**patches):
    settings = Document().settings.to_json()
    settings["patches"].update(patches)
    return settings


# Hand-edited values of the wrong type: each names its field (bool("no") is True, int("3") is 3:
# the reader never coerces)
@pytest.mark.parametrize("change, message", [
    ({"targets": [{"name": "a", "path": "", "visible": "no", "points": "targets/0"}]},
     r"targets\[0\]\.visible must be true or false, got 'no'"),
    ({"targets": [{"name": "a", "path": 7, "visible": True, "points": "targets/0"}]},
     r"targets\[0\]\.path must be text"),
    ({"fitted": _fitted_surface(degree_u="3")}, "fitted: degree_u must be an integer, got '3'"),
    ({"fitted": _fitted_surface(degree_v=3.0)}, "fitted: degree_v must be an integer, got 3.0"),
    ({"fitted": _fitted_surface(knots_u=["0"] * 4 + ["1"] * 4)},
     "fitted: knots_u must hold numbers"),
    ({"patches": [{"name": "p", "geometry": _fitted_surface(degree_u=True)}]},
     r"patches\[0\] \(p\): degree_u must be an integer, got True"),
    ({"settings": _settings(degree_u="3")}, "degree_u must be an integer, got '3'"),
    ({"settings": _settings(free_knots="no")}, "free_knots must be true or false, got 'no'"),
    ({"settings": _settings(parameter_correction=0)},
     "parameter_correction must be true or false"),
    ({"settings": _patch_settings(degree="3")}, "degree must be an integer, got '3'"),
    ({"settings": _patch_settings(tolerance="0.1")},
     "tolerance must be a positive number, got '0.1'"),
    ({"settings": _patch_settings(max_size=10**6)}, "max_size must be an integer from 4 to 40"),
    ({"settings": {**Document().settings.to_json(), "show_offsets": "no"}},
     "show_offsets must be true or false, got 'no'"),
    ({"settings": {**Document().settings.to_json(), "fit_mode": "both"}},
     "fit_mode must be one of single, patches"),
    ({"settings": {**Document().settings.to_json(), "offset_distance": "0.1"}},
     "offset_distance must be a finite number"),
    ({"targets": {"name": "a"}}, "targets must be a list"),
])
def test_values_of_the_wrong_type_are_refused_naming_the_field(tmp_path, change, message):
    path = _zip(tmp_path / "bad.nstudio", {MANIFEST: json.dumps(_manifest(**change)),
                                           "targets/0.npy": _npy(GOOD_POINTS)})
    document = _document(np.ones((3, 3)))
    before = (document.targets, document.settings, document.fitted)
    with pytest.raises(ValueError, match=message):
        load_session(document, path)
    assert (document.targets, document.settings, document.fitted) == before


def test_a_json_session_of_points_as_text_is_refused(tmp_path):
    from app.state import JSON_SESSION_FORMAT, Settings

    path = tmp_path / "old.json"
    path.write_text(json.dumps({"format": JSON_SESSION_FORMAT, "settings": Settings().to_json(),
                                "targets": [{"name": "a", "points": [["0", "0", "0"]] * 4}],
                                "patches": [], "fitted": None}))
    with pytest.raises(ValueError, match=r"targets\[0\]\.points must hold numbers"):
        read_session(path)


@pytest.mark.parametrize("report, deviation, message", [
    ({"deviation": "network_deviation"}, np.full(4, np.nan), "NaN at every point"),
    ({"deviation": "network_deviation"}, np.array([0.1, np.inf, 0.2, 0.3]), "infinite"),
    ({"deviation": [0.1, 0.2, 0.3, 0.4]}, None, "deviation must name its member"),
    ({"passes": "7"}, None, "passes must be a whole number, got '7'"),
    ({"elapsed": "3.5"}, None, "elapsed must be a number of seconds"),
    ({"rms": "0.1"}, None, "rms must be a number or null"),
    ({"warnings": "seams"}, None, "warnings must be a list of text"),
    ({"event": "fitted"}, None, "event must be 'done' or 'stopped'"),
    ({"quality": {"patches": "6"}}, None, "quality must be an object of numbers"),
])
def test_a_damaged_network_report_is_refused(tmp_path, report, deviation, message):
    from nurbs_core.io.network_io import network_document

    arrays = {"targets/0": GOOD_POINTS}
    if deviation is not None:
        arrays["network_deviation"] = deviation
    path = tmp_path / "bad.nstudio"
    write_archive(path, _manifest(network="network.json", network_report=report), arrays,
                  {"network.json": network_document(_cube_network())})
    with pytest.raises(ValueError, match=message):
        read_session(path)


def test_a_deviation_of_a_selection_fit_keeps_its_nan_points(tmp_path):
    """NaN marks the points a fit of a selection left out: a report with some NaN opens."""
    from nurbs_core.io.network_io import network_document

    deviation = np.array([0.1, np.nan, 0.2, np.nan])
    path = tmp_path / "ok.nstudio"
    write_archive(path, _manifest(network="network.json",
                                  network_report={"deviation": "network_deviation",
                                                  "passes": 3, "rms": None}),
                  {"targets/0": GOOD_POINTS, "network_deviation": deviation},
                  {"network.json": network_document(_cube_network())})
    np.testing.assert_array_equal(read_session(path)["network_report"]["deviation"], deviation)


def test_a_damaged_network_member_is_refused(tmp_path):
    from nurbs_core.io.network_io import network_document

    document = network_document(_cube_network())
    document["control_points"][0][0] += 1.0  # the patches no longer agree with the net
    path = tmp_path / "bad.nstudio"
    write_archive(path, _manifest(network="network.json"), {"targets/0": GOOD_POINTS},
                  {"network.json": document})
    with pytest.raises(ValueError, match="damaged session.*disagrees with the network"):
        read_session(path)


def test_a_failed_save_leaves_the_old_file(tmp_path):
    path = tmp_path / "work.nstudio"
    path.write_bytes(b"old")
    document = _document(np.ones((3, 3)))
    document.set_network(object())  # not a network: encoding fails before the file is touched
    with pytest.raises(AttributeError):
        save_session(document, path)
    assert path.read_bytes() == b"old"
