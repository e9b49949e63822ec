"""The damaged-session fault suite (issue 30, item 4): one complete session (a cloud, a loaded
patch, a fitted surface, a patch network with its report) damaged one way at a time (cut short,
NaN points, points of 2 columns, knot counts and degrees that do not match, missing entries,
values of the wrong type, sizes the file cannot hold, a compressed member, another file renamed).
Each is refused by one line in the user's terms (which part of the session is wrong, no raw
``KeyError``) and the open document keeps what it had; the undamaged session opens."""

from __future__ import annotations

import copy
import io
import json
import re
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.session_file import MANIFEST, load_session, read_session, save_session
from app.state import JSON_SESSION_FORMAT, Document, Settings, Target
from nurbs_core.geometry_arrays import SurfaceArrays
from nurbs_core.patches.network import build_network

POINTS = np.random.default_rng(0).normal(size=(300, 3))


def _surface() -> SurfaceArrays:
    u = np.linspace(0.0, 1.0, 4)
    grid = np.stack([*np.meshgrid(u, u, indexing="ij"), np.zeros((4, 4))], -1)
    knots = np.array([0, 0, 0, 0, 1, 1, 1, 1], float)
    return SurfaceArrays(3, 3, grid, np.ones((4, 4)), knots, knots.copy())


def _network():
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4],
                      [1, 5, 7, 3]])
    return build_network(corners, quads, size=5, degree=3)


@pytest.fixture(scope="module")
def good_members(tmp_path_factory) -> dict[str, bytes]:
    """The members of a complete session archive."""
    document = Document()
    document.replace_content([Target("scan", POINTS, "/data/scan.ply")], [_surface()], ["p0"])
    document.set_fitted(_surface())
    document.set_network(_network())
    path = tmp_path_factory.mktemp("good") / "good.nstudio"
    save_session(document, path, {"event": "done", "passes": 2, "elapsed": 1.0,
                                  "deviation": np.random.default_rng(1).random(len(POINTS))})
    with zipfile.ZipFile(path) as archive:
        return {name: archive.read(name) for name in archive.namelist()}


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, array)
    return buffer.getvalue()


def _zip(members: dict[str, bytes], compression: int = zipfile.ZIP_STORED) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", compression) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return buffer.getvalue()


Members = dict[str, bytes]


def _manifest(change: Callable[[dict[str, Any]], Any]) -> Callable[[Members], bytes]:
    def damage(members: Members) -> bytes:
        manifest = json.loads(members[MANIFEST])
        change(manifest)
        return _zip({**members, MANIFEST: json.dumps(manifest).encode()})
    return damage


def _network_member(change: Callable[[dict[str, Any]], Any]) -> Callable[[Members], bytes]:
    def damage(members: Members) -> bytes:
        document = json.loads(members["network.json"])
        change(document)
        return _zip({**members, "network.json": json.dumps(document).encode()})
    return damage


def _member(name: str, data: bytes) -> Callable[[Members], bytes]:
    return lambda members: _zip({**members, name: data})


def _json_session(points: Any) -> Callable[[Members], bytes]:
    """A session of the JSON format before the archive holding ``points``."""
    return lambda _members: json.dumps({
        "format": JSON_SESSION_FORMAT, "settings": Settings().to_json(),
        "targets": [{"name": "a", "points": points}], "patches": [], "fitted": None}).encode()


def _cut(members: Members) -> bytes:
    whole = _zip(members)
    return whole[: len(whole) // 2]


_nan_points = POINTS.copy()
_nan_points[7, 2] = np.nan
_huge = _npy(POINTS).replace(b"(300, 3)", b"(300000000, 3)")

CASES: list[tuple[str, Callable[[Members], bytes], str]] = [
    ("truncated archive", _cut, "the archive is truncated or corrupt"),
    ("truncated manifest", lambda m: _zip({**m, MANIFEST: m[MANIFEST][:100]}),
     "session.json is not valid JSON"),
    ("truncated network", lambda m: _zip({**m, "network.json": m["network.json"][:200]}),
     "network.json is not valid JSON"),
    ("truncated json session", lambda m: _json_session([[0, 0, 0]])(m)[:50], "not valid JSON"),
    ("NaN point", _member("targets/0.npy", _npy(_nan_points)), "NaN or infinite coordinates"),
    ("json NaN point", _json_session([[0, 0, 0], [1, 0, float("nan")]]),
     "NaN or infinite coordinates"),
    ("2-column points", _member("targets/0.npy", _npy(POINTS[:, :2].copy())),
     r"expected \(N, 3\) coordinates, got an array of shape \(300, 2\)"),
    ("json 2-column points", _json_session([[0, 0], [1, 0], [2, 2]]),
     r"expected \(N, 3\) coordinates, got an array of shape \(3, 2\)"),
    ("flat points", _member("targets/0.npy", _npy(POINTS.reshape(-1))),
     r"got an array of shape \(900,\)"),
    ("fitted knot count", _manifest(lambda m: m["fitted"]["knots_u"].append(1.0)),
     "fitted: knots_u: 4 control points of degree 3 need 8 knots, got 9"),
    ("patch negative degree", _manifest(lambda m: m["patches"][0]["geometry"].update(
        degree_v=-1)), r"patches\[0\] \(p0\): knots_v: degree -1 must be at least 1"),
    ("fitted degree as text", _manifest(lambda m: m["fitted"].update(degree_u="3")),
     "degree_u must be an integer"),
    ("fitted NaN control point", _manifest(
        lambda m: m["fitted"]["control_points"][0][0].__setitem__(0, None)),
     "control_points must hold numbers"),
    ("fitted zero weights", _manifest(lambda m: m["fitted"].update(weights=[[0.0] * 4] * 4)),
     "weights must be finite and positive"),
    ("fitted several surfaces", _manifest(lambda m: m["fitted"].update(
        control_points=[m["fitted"]["control_points"]] * 2, weights=[m["fitted"]["weights"]] * 2)),
     "several shapes, not one"),
    ("network wrong knot count", _network_member(lambda n: n["knots"].pop()),
     "knots has shape"),
    ("network degree beyond size", _network_member(lambda n: n.update(degree=40)),
     "a patch of degree 40 needs more than 40 control points"),
    ("network NaN control point", _network_member(
        lambda n: n["layout"]["vertices"][0].__setitem__(0, float("nan"))), "NaN or infinite"),
    ("network 2-column control points", _network_member(
        lambda n: n.update(control_points=[c[:2] for c in n["control_points"]])),
     "control_points has shape"),
    # 6 quads declared 20000 x 20000 control points each: the layout allocated 18 GB (killed)
    ("network huge declared size", _network_member(lambda n: n.update(size=20000)),
     r"the patch network \(network.json\): size 20000 and the 6 layout quads need an index map "
     r"of 6 x 20000 x 20000, the file holds 6 x 5 x 5"),
    ("network missing layout", _network_member(lambda n: n.pop("layout")),
     "the network lacks the \"layout\" object"),
    ("target missing points", _manifest(lambda m: m["targets"][0].pop("points")),
     r"targets\[0\] needs the name of its points"),
    ("patch missing geometry", _manifest(lambda m: m["patches"][0].pop("geometry")),
     r"patches\[0\] \(p0\) needs its geometry"),
    ("patch missing name", _manifest(lambda m: m["patches"][0].pop("name")),
     r"patches\[0\] needs a name"),
    ("patch not an object", _manifest(lambda m: m.update(patches=[5])),
     r"patches\[0\] needs a name"),
    ("settings not an object", _manifest(lambda m: m.update(settings=5)),
     "settings must be an object, got a number"),
    ("fit settings as text", _manifest(lambda m: m["settings"].update(fit="fast")),
     "settings.fit must be an object, got a string"),
    ("offset distance as text", _manifest(lambda m: m["settings"].update(offset_distance="0.1")),
     "offset_distance must be a finite number"),
    # the dock showed 1,000,000 (its maximum) while the offsets were computed at 1e300
    ("offset distance beyond the dock", _manifest(
        lambda m: m["settings"].update(offset_distance=1e300, show_offsets=True)),
     "offset_distance 1e[+]300 is beyond the Offsets dock's range"),
    # every cloud named the one member: each read copied it (a 24 MB file, 240 GB of clouds)
    ("one member for many clouds", _manifest(
        lambda m: m.update(targets=[m["targets"][0]] * 10_000)),
     "targets/0.npy is named twice"),
    ("targets an object", _manifest(lambda m: m.update(targets={"a": 1})),
     "targets must be a list"),
    ("visible as text", _manifest(lambda m: m["targets"][0].update(visible="no")),
     "visible must be true or false"),
    ("unknown units", _manifest(lambda m: m.update(units="furlongs")), "unknown units"),
    ("report passes as text", _manifest(lambda m: m["network_report"].update(passes="2")),
     "network_report.passes must be a whole number"),
    ("deviation of two columns", _member("network_deviation.npy", _npy(np.zeros((300, 2)))),
     "one value per point"),
    ("huge declared array", _member("targets/0.npy", _huge), "more than it holds"),
    ("compressed (bomb) member", lambda m: _zip(
        {**m, "targets/0.npy": _npy(np.zeros((2_000_000, 3)))}, zipfile.ZIP_DEFLATED),
     "compressed or larger than the file"),
    ("deep nesting", lambda m: _zip({**m, MANIFEST: b"[" * 100_000 + b"]" * 100_000}),
     "nested too deeply"),
    ("another zip renamed", lambda _m: _zip({"hello.txt": b"hi"}),
     "not a NURBS Studio session .a zip archive without session.json"),
    ("a PLY renamed", lambda _m: b"ply\nformat ascii 1.0\nelement vertex 1\nend_header\n1\n",
     "not a NURBS Studio session"),
]


def test_the_undamaged_session_opens(tmp_path, good_members):
    path = tmp_path / "good.nstudio"
    path.write_bytes(_zip(good_members))
    session = read_session(path)
    assert session["targets"][0].points.shape == (300, 3)
    assert session["network"].patch_count == 6 and session["fitted"] is not None


@pytest.mark.parametrize("label, damage, message", CASES, ids=[c[0] for c in CASES])
def test_a_damaged_session_is_one_clear_line_and_the_document_is_untouched(
        tmp_path, good_members, label, damage, message):
    path = Path(tmp_path / "damaged.nstudio")
    path.write_bytes(damage(copy.deepcopy(good_members)))
    document = Document()
    document.replace_content([Target("open", np.eye(3), "")], [], [])
    before = (document.targets, document.settings, document.fitted, document.network)
    with pytest.raises(ValueError, match=message) as refused:
        load_session(document, path)
    text = str(refused.value)
    assert text.startswith(str(path)) and "\n" not in text
    assert "KeyError" not in text and "TypeError" not in text
    assert (document.targets, document.settings, document.fitted, document.network) == before


WINDOW_CASES = ["NaN point", "2-column points", "network huge declared size", "truncated archive",
                "fitted several surfaces", "a PLY renamed"]


def test_the_window_refuses_damaged_sessions_and_keeps_its_document(
        qtbot, window, ply_cloud, tmp_path, good_members, caplog):
    """Through File > Open Session (the load job): each damaged session ends the open with
    ``files_loaded(False)``, one message naming the part and saying the document is unchanged,
    no traceback logged, the cloud still open."""
    from app_helpers import open_by_drop

    open_by_drop(qtbot, window, [ply_cloud[0]])
    targets = window.document.targets
    damages = {label: (damage, message) for label, damage, message in CASES}
    for label in WINDOW_CASES:
        damage, message = damages[label]
        path = tmp_path / f"{label.replace(' ', '_')}.nstudio"
        path.write_bytes(damage(copy.deepcopy(good_members)))
        with qtbot.waitSignal(window.files_loaded, timeout=30000) as opened:
            window.open_session(str(path))
        assert opened.args == [False], label
        first, second = window.last_error.split("\n")
        assert second == "The document was left unchanged."
        assert first.startswith(str(path)) and re.search(message, first), first
        assert window.document.targets is targets and window.document.network is None
    assert not [record for record in caplog.records if record.exc_info], "a traceback was logged"
    # the offset distance a session may hold is the one the Offsets dock can show
    from app.state import MAX_OFFSET_DISTANCE

    box = window.offset_panel.distance
    assert (box.minimum(), box.maximum()) == (-MAX_OFFSET_DISTANCE, MAX_OFFSET_DISTANCE)
