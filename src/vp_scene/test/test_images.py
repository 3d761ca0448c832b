"""vp_scene.images: an image's size is read from its header and checked before anything is
decoded; a truncated or corrupt PNG or JPEG is refused, for a
file and for the fleet's ``sensor_msgs/CompressedImage``."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from PIL import Image

from vp_scene import messages as m
from vp_scene.images import MAX_IMAGE_PIXELS, ImageError, decode_image, read_image


@pytest.fixture
def no_decoding(monkeypatch):
    """A tripwire: OpenCV's decoders fail the test (a 30000 x 30000 image decodes to 2.7 GB)."""
    def decode(*_args, **_kwargs):
        pytest.fail("an image was decoded")

    monkeypatch.setattr(cv2, "imdecode", decode)
    monkeypatch.setattr(cv2, "imread", decode)


def _smooth(h: int = 120, w: int = 160) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    return np.stack([x * 255 // w, y * 255 // h, (x + y) * 255 // (w + h)], axis=2).astype(np.uint8)


def test_an_oversize_image_is_refused_from_its_header(tmp_path: Path, no_decoding) -> None:
    """A 30000 x 30000 PNG is 0.1 MB here (1 bit, zeros) and 2.7 GB decoded: refused, as a file
    and as a CompressedImage, with one line giving its size, and nothing decoded."""
    huge = tmp_path / "huge.png"
    Image.new("1", (30000, 30000)).save(huge)
    with pytest.raises(ImageError) as err:
        read_image(huge)
    text = str(err.value)
    assert text.startswith(f"{huge}: 30000x30000 pixels (900 MP)") and "at most 150 MP" in text and "\n" not in text
    assert MAX_IMAGE_PIXELS == 150_000_000
    msg = m.compressed_image_msg(np.zeros((2, 2, 3), np.uint8), "d0/camera_optical", m.PoseStamped().header.stamp)
    msg.data = huge.read_bytes()
    with pytest.raises(ValueError, match=r"^compressed image \(rgb8; png compressed bgr8, \d+ bytes\): 30000x30000"):
        m.compressed_image_array(msg)


def test_truncated_and_corrupt_images_are_refused(tmp_path: Path) -> None:
    """A truncated JPEG (cv2.imread of the file fills its lower half with grey), a truncated PNG
    and a PNG with a damaged byte: refused naming the file; the intact ones read as OpenCV reads
    them (PNG: exactly)."""
    rgb = _smooth()
    for ext in ("jpg", "png"):
        path = tmp_path / f"good.{ext}"
        cv2.imwrite(str(path), rgb[..., ::-1])
        whole = path.read_bytes()
        assert np.array_equal(read_image(path), cv2.imread(str(path))[..., ::-1])
        cut = tmp_path / f"cut.{ext}"
        cut.write_bytes(whole[: len(whole) * 2 // 3])
        with pytest.raises(ImageError, match=rf"^{cut}: corrupt or truncated (JPEG|PNG) \("):
            read_image(cut)
        with pytest.raises(ImageError, match="truncated"):
            decode_image(cut.read_bytes(), "a message")
    assert cv2.imread(str(tmp_path / "cut.jpg")) is not None  # what the suite read before
    damaged = bytearray((tmp_path / "good.png").read_bytes())
    damaged[len(damaged) // 2] ^= 0xFF
    (tmp_path / "damaged.png").write_bytes(bytes(damaged))
    with pytest.raises(ImageError, match=r"damaged.png: corrupt or truncated PNG \(.*checksum"):
        read_image(tmp_path / "damaged.png")
    (tmp_path / "text.png").write_text("not an image")
    with pytest.raises(ImageError, match=r"text.png: does not decode \(corrupt, or not a PNG or JPEG\)$"):
        read_image(tmp_path / "text.png")
    with pytest.raises(ImageError, match="cannot read"):
        read_image(tmp_path / "missing.png")


def test_a_small_image_in_a_huge_file_is_refused_before_the_file_is_read(tmp_path: Path) -> None:
    path = tmp_path / "padded.jpg"
    cv2.imwrite(str(path), _smooth(16, 16))
    with open(path, "ab") as f:
        f.truncate(20 << 20)  # 20 MB (sparse) after a 16 x 16 JPEG
    with pytest.raises(ImageError, match=r"padded.jpg: 20971520 bytes for 16x16 pixels"):
        read_image(path)
