"""Image files (atomic writes, read back through OpenImageIO), labels, legend, contact sheets."""
import os

import numpy as np
import OpenImageIO as oiio
import pytest

from facedyn.preview import colormap, images, text


def solid(color, h=20, w=30):
    return np.broadcast_to(np.array(color, np.uint8), (h, w, 3)).copy()


def test_png_round_trip_is_exact_and_leaves_no_temporary_file(tmp_path):
    rng = np.random.default_rng(0)
    pixels = rng.integers(0, 256, (17, 23, 3), dtype=np.uint8)
    path = images.write_image(tmp_path / "frame.0001.png", pixels)
    inp = oiio.ImageInput.open(str(path))
    assert (inp.spec().width, inp.spec().height, inp.spec().nchannels) == (23, 17, 3)
    back = inp.read_image(oiio.UINT8)
    inp.close()
    assert np.array_equal(back, pixels)
    images.write_image(path, 255 - pixels)  # replacing an existing file
    assert np.array_equal(images.read_image(path)[0], 255 - pixels)
    assert os.listdir(tmp_path) == ["frame.0001.png"]


def test_jpeg_is_close_and_exr_keeps_floats_and_metadata(tmp_path):
    pixels = np.zeros((32, 32, 3), np.uint8)
    pixels[:, 16:] = (200, 40, 90)
    back, _ = images.read_image(images.write_image(tmp_path / "a.jpg", pixels))
    assert np.abs(back.astype(int) - pixels).mean() < 4
    values = np.linspace(-1, 1, 4 * 5 * 4, dtype=np.float32).reshape(4, 5, 4)
    path = images.write_image(tmp_path / "a.exr", values, {"facedyn:frame": 7, "facedyn:units": "cm"})
    back, attributes = images.read_image(path)
    np.testing.assert_array_equal(back, values)
    assert attributes["facedyn:frame"] == 7 and attributes["facedyn:units"] == "cm"
    assert attributes["channelnames"] == ("R", "G", "B", "A")


def test_bad_destinations_and_pixels_are_refused_cleanly(tmp_path, monkeypatch):
    pixels = solid((1, 2, 3))
    missing = tmp_path / "nope" / "x.png"
    with pytest.raises(ValueError, match=f"folder {tmp_path / 'nope'} does not exist"):
        images.write_image(missing, pixels)
    with pytest.raises(ValueError, match="no writer for '.xyz'"):
        images.write_image(tmp_path / "x.xyz", pixels)
    with pytest.raises(ValueError, match="pixels must be"):
        images.write_image(tmp_path / "x.png", np.zeros((4, 4, 5), np.uint8))
    with pytest.raises(ValueError, match="attribute 'k'"):
        images.write_image(tmp_path / "x.png", pixels, {"k": [1, 2]})
    monkeypatch.setattr(os, "access", lambda *_: False)
    with pytest.raises(ValueError, match=f"folder {tmp_path} is not writable"):
        images.write_image(tmp_path / "x.png", pixels)
    assert os.listdir(tmp_path) == []


def test_text_is_drawn_near_its_anchor_only():
    image = np.zeros((60, 200, 3), np.uint8)
    text.draw_text(image, "-1.5 mm +2:0", 10, 20, 16)
    ys, xs = np.nonzero(image.max(-1) > 100)
    w, h = text.text_size("-1.5 mm +2:0", 16)
    assert w > 60 and 10 <= h <= 24
    assert xs.min() >= 9 and xs.max() <= 10 + w + 1 and ys.min() >= 19 and ys.max() <= 20 + h + 1
    assert text.text_size("0000", 16)[0] > text.text_size("00", 16)[0]


def test_colour_map_and_legend():
    np.testing.assert_allclose(colormap.diverging(0.0, 2.0), colormap.ZERO, atol=1e-6)
    np.testing.assert_allclose(colormap.diverging([2.0, 5.0], 2.0), [colormap.POSITIVE] * 2, atol=1e-6)
    np.testing.assert_allclose(colormap.diverging(-3.0, 2.0), colormap.NEGATIVE, atol=1e-6)
    offsets = np.array([[[0.0, 0.0, 0.1], [0.0, 0.3, 0.0]]])
    normals = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    np.testing.assert_allclose(colormap.normal_component_mm(offsets, normals), [[-1.0, 3.0]], atol=1e-6)
    with pytest.raises(ValueError, match="do not match"):
        colormap.normal_component_mm(offsets, normals[:1])
    legend = colormap.legend(2.0, height=200)
    bar = legend[:, 12]  # a column through the colour bar
    top, bottom = bar[np.nonzero(bar.max(-1) > 100)[0][[0, -1]]].astype(int)
    assert top[1] > top[0] + 100 and bottom[0] > bottom[1] + 100
    assert (legend[:, 40:].max(-1) > 150).any()  # tick labels


def test_contact_sheet_places_rows_columns_labels_and_legend(tmp_path):
    colours = {"captured": (200, 0, 0), "quasistatic": (0, 200, 0), "synthesized": (0, 0, 200)}
    rows = [(name, [solid(c), solid(tuple(v // 2 for v in c))]) for name, c in colours.items()]
    legend = colormap.legend(1.0, height=80, font_size=12)
    sheet = images.contact_sheet(rows, [1001, 1042], legend, font_size=14, gap=6)
    bg = sheet[0, 0].copy()
    for name, c in colours.items():
        ys, xs = np.nonzero((sheet == c).all(-1))
        assert len(ys) == 20 * 30 and np.ptp(ys) == 19 and np.ptp(xs) == 29
        left = sheet[ys.min() : ys.max() + 1, : xs.min() - 6]
        assert (left != bg).any(), f"no label left of row {name}"
    first_cell_top = np.nonzero((sheet == (200, 0, 0)).all(-1))[0].min()
    assert (sheet[: first_cell_top - 2] != bg).any()  # frame numbers above the cells
    assert (sheet[:, -legend.shape[1] - 6 :] != bg).any()
    back, _ = images.read_image(images.write_image(tmp_path / "sheet.png", sheet))
    assert np.array_equal(back, sheet)
    with pytest.raises(ValueError, match="row 'x' has 1 images for 2 frame labels"):
        images.contact_sheet([("x", [solid((0, 0, 0))])], [1, 2])
    with pytest.raises(ValueError, match="among images of"):
        images.contact_sheet([("x", [solid((0, 0, 0)), solid((0, 0, 0), 10, 10)])], [1, 2])
