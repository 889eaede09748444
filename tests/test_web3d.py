"""Browser 3D views and slider explorers of `handmesh_tutorial.viz`, checked without a browser:
the payload decoded back (meshes, camera), its size, the static picture each view carries (for
pages without JavaScript or WebGL), no request to another host in the HTML, the static strip of
an explorer, and the docs build's treatment of both (tools/mkdocs_hooks.py).
`make docs-check` runs the views in headless Chromium."""

import base64
import importlib.util
import io
import re
import struct
from pathlib import Path

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from PIL import Image  # noqa: E402

from handmesh_tutorial import hand, viz  # noqa: E402

umsgpack = pytest.importorskip("umsgpack")
ROOT = Path(__file__).resolve().parents[1]
EXTERNAL = re.compile(r"(https?:)?//[a-z0-9.-]+\.[a-z]{2,}|src=[\"']//", re.I)


def _commands(view) -> list[dict]:
    out, data, off = [], view.payload, 0
    while off < len(data):
        (n,) = struct.unpack_from("<I", data, off)
        out.append(umsgpack.unpackb(data[off + 4:off + 4 + n]))
        off += 4 + n
    assert off == len(data)
    return out


def _typed(attr: dict) -> np.ndarray:
    dtypes = {"Float32Array": np.float32, "Uint16Array": np.uint16, "Uint32Array": np.uint32,
              "Uint8Array": np.uint8}
    return np.frombuffer(attr["array"].data, dtype=dtypes[attr["type"]])


@pytest.fixture(scope="module")
def right_hand():
    model = hand.HandModel("right")
    return np.asarray(model.template_vertices), np.asarray(model.faces), model.vertex_colors()


def test_a_hand_view_decodes_to_its_mesh_and_stays_small(right_hand):
    v, f, colors = right_hand
    view = viz.view_hand(v, f, colors=colors)
    cmds = _commands(view)
    mesh = next(c for c in cmds if c["type"] == "set_object" and c["path"] == "/hmt/hand")
    geom = mesh["object"]["geometries"][0]["data"]
    assert np.allclose(_typed(geom["attributes"]["position"]).reshape(-1, 3), v, atol=1e-6)
    assert np.array_equal(_typed(geom["index"]).reshape(-1, 3), f)
    rgb = _typed(geom["attributes"]["color"]).reshape(-1, 3) / 255.0
    assert np.abs(rgb - colors).max() <= 0.5 / 255 + 1e-9
    assert len(view.payload) < 40_000, len(view.payload)   # ~24 kB for the 778-vertex hand
    assert view.payload == viz.view_hand(v, f, colors=colors).payload   # same view, same bytes


def test_the_browser_camera_is_the_shared_hand_camera(right_hand):
    v, f, _ = right_hand
    cmds = _commands(viz.view_hand(v, f))
    world = np.array(next(c for c in cmds if c["path"] == "/hmt")["matrix"]).reshape(4, 4).T
    cam = next(c for c in cmds if c["path"] == "/Cameras/default/rotated/<object>"
               and c.get("property") == "position")["value"]
    # meshcat's camera node is turned +90 degrees about x (three.js y-up in its z-up world);
    # the orbit target is the world origin
    rot_x = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    eye_world = rot_x @ np.asarray(cam)
    eye_data = world[:3, :3].T @ eye_world                   # back into the hand's frame
    target = world[:3, :3].T @ -world[:3, 3]
    assert np.allclose(target, 0.5 * (v.min(0) + v.max(0)), atol=1e-9)
    assert np.allclose(eye_data / np.linalg.norm(eye_data), -viz.view_direction(viz.HAND_VIEW),
                       atol=1e-9)
    assert np.allclose(world[:3, :3].T @ [0, 0, 1], [0, 1, 0], atol=1e-12)  # screen up: +y
    # the whole hand fits the 30-degree field of view
    r = np.linalg.norm(v - target, axis=1).max()
    assert np.linalg.norm(eye_data) * np.sin(np.radians(15)) > r


def test_view_html_loads_nothing_from_another_host(right_hand):
    v, f, _ = right_hand
    view = viz.view_prediction(v, v + 0.002, f, pred_joints=np.zeros((21, 3)),
                               gt_joints=np.zeros((21, 3)))
    inline, with_viewer = view.html(), view.html(viewer=True)
    saved = view.html(src="v.bin", picture_src="v.jpg")
    for page in (inline, with_viewer, saved):
        assert not EXTERNAL.search(page), EXTERNAL.search(page).group(0)
        assert 'class="hmt-view"' in page
    assert 'data-src="v.bin"' in saved and "data-payload" not in saved
    assert 'class="hmt-view-picture" src="v.jpg"' in saved
    # two hands: ~61 kB of commands and a ~20 kB picture, both base64
    assert len(saved) < 2_000 and len(inline) < 130_000
    viewer_b64 = re.search(r'class="hmt-viewer-js">([^<]+)<', with_viewer).group(1)
    assert len(viewer_b64) < 400_000                          # gzip, base64: ~290 kB
    assert viz.viewer_js_path().is_file()


def test_view_meshes_names_the_bad_mesh():
    with pytest.raises(ValueError, match="mesh 'box'.*\\(V, 3\\)"):
        viz.view_meshes({"box": (np.zeros((4, 2)), np.zeros((1, 3), int))})
    with pytest.raises(ValueError, match="mesh 'box'.*\\[0, 3\\)"):
        viz.view_meshes({"box": (np.zeros((3, 3)), [[0, 1, 3]])})
    with pytest.raises(ValueError, match="at least one mesh"):
        viz.view_meshes({})


def test_view_save_writes_the_payload(tmp_path, right_hand):
    v, f, _ = right_hand
    view = viz.view_hand(v, f)
    path = view.save(tmp_path / "views" / "hand.bin")
    assert path.read_bytes() == view.payload
    picture = view.save_picture(tmp_path / "views" / "hand.jpg")
    assert picture.read_bytes() == view.picture()
    with pytest.raises(ValueError, match="no picture"):
        viz.View3D(view.commands, 380, view.camera).save_picture(tmp_path / "x.jpg")


def _decode_picture(page: str) -> Image.Image:
    m = re.search(r'<img class="hmt-view-picture" src="data:image/jpeg;base64,([^"]+)"', page)
    assert m, "the view's HTML carries no inline picture"
    return Image.open(io.BytesIO(base64.b64decode(m.group(1))))


def test_a_view_carries_a_static_picture_of_its_meshes(right_hand):
    """Without JavaScript or WebGL (GitHub's notebook view, a browser without WebGL) a view is a
    picture, not an empty box: inline in its HTML, and as image/jpeg in the notebook output."""
    v, f, _ = right_hand
    view = viz.view_hand(v, f, colors="#ff0000", height=300)
    page = view.html()
    image = _decode_picture(page)
    assert image.format == "JPEG" and image.size == (400, 300)
    rgb = np.asarray(image.convert("RGB")).astype(int)
    red = (rgb[..., 0] > 120) & (rgb[..., 1] < 80) & (rgb[..., 2] < 80)
    # the hand (red, shaded) fills a good part of the picture, cropped to it; the rest is the
    # light background
    assert 0.15 < red.mean() < 0.8, red.mean()
    assert (rgb.min(-1) > 230).mean() > 0.1
    rows, cols = np.nonzero(red)
    assert rows.min() < 0.2 * 300 or rows.max() > 0.8 * 300 or cols.min() < 0.2 * 400
    assert len(view.picture()) < 40_000, len(view.picture())   # ~10-20 kB
    assert view.picture() == viz.view_hand(v, f, colors="#ff0000", height=300).picture()
    # the note says what the picture is; hmt_views.js removes both once the live view draws
    assert "Static picture" in page
    js = (ROOT / "handmesh_tutorial" / "viz" / "hmt_views.js").read_text()
    assert 'querySelector(".hmt-view-picture")' in js
    bundle = view._repr_mimebundle_()
    assert base64.b64decode(bundle["image/jpeg"]) == view.picture()
    assert _decode_picture(bundle["text/html"]).size == (400, 300)


def test_the_picture_draws_every_mesh_and_skeleton(right_hand):
    v, f, _ = right_hand
    joints = np.linspace(v.min(0), v.max(0), 21)
    view = viz.view_prediction(v, v + 0.003, f, pred_joints=joints, gt_joints=joints)
    rgb = np.asarray(Image.open(io.BytesIO(view.picture())).convert("RGB")).astype(int)
    blueish = (rgb[..., 2] > rgb[..., 0] + 40).mean()      # the translucent ground truth
    dark = (rgb.max(-1) < 60).mean()                        # the black true skeleton
    assert blueish > 0.02 and dark > 0.001, (blueish, dark)


def test_view_height_is_checked(right_hand):
    v, f, _ = right_hand
    with pytest.raises(ValueError, match="height must be at least 50"):
        viz.view_hand(v, f, height=10)


def _figure(a, b="x"):
    fig, ax = plt.subplots(figsize=(1.5, 1))
    ax.plot([0, 1], [0, a])
    ax.set_title(f"{a} {b}")
    return fig


def test_explore_strip_renders_one_labelled_frame_per_value():
    ex = viz.explore(_figure, {"a": [0, 10, 20, 30, 40, 50, 60], "b": ["x", "y"]}, n_frames=4)
    assert ex.frames == [{"a": a, "b": "y"} for a in (0, 20, 40, 60)]   # b starts in its middle
    strip = ex.strip_html()
    pngs = re.findall(r'src="data:image/png;base64,([^"]+)"', strip)
    assert len(pngs) == 4
    for data in pngs:
        assert Image.open(io.BytesIO(base64.b64decode(data))).size[0] > 20
    assert re.findall(r"<figcaption[^>]*>([^<]+)<", strip)[1] == "a = 20, b = y"
    assert not EXTERNAL.search(strip)
    assert len(strip) < 300_000


def test_explore_names_unknown_frames():
    with pytest.raises(ValueError, match="unknown parameters \\['c'\\]"):
        viz.explore(_figure, {"a": [1, 2]}, frames=[{"c": 1}])
    with pytest.raises(ValueError, match="not among their options"):
        viz.explore(_figure, {"a": [1, 2]}, frames=[{"a": 3}])
    with pytest.raises(ValueError, match="no option"):
        viz.explore(_figure, {"a": []})


def _hooks():
    path = ROOT / "tools" / "mkdocs_hooks.py"
    spec = importlib.util.spec_from_file_location("mkdocs_hooks", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_docs_build_drops_the_inline_viewer_and_shows_an_explorers_strip():
    hooks = _hooks()
    for view in ('<script type="application/octet-stream" class="hmt-viewer-js">QUJD</script>',
                 '<script class="hmt-viewer-js" type="application/octet-stream">QUJD</script>'):
        assert hooks._strip_inline_viewer(view + "\n<div>") == "\n<div>"   # nbconvert's order too
    widget = ('<script type="text/javascript">\nvar element = document.getElementById("x");\n'
              '</script>\n<script type="application/vnd.jupyter.widget-view+json">\n'
              '{"model_id": "abc", "version_major": 2, "version_minor": 0, '
              '"hmt_fallback": "<div class=\\"hmt-explore-strip\\">frames</div>"}\n</script>')
    out = hooks._static_widgets(widget, "nb.ipynb")
    assert '<div class="hmt-explore-strip">frames</div>' in out
    assert "widget-view" not in out
