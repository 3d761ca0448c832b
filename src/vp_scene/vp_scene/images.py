"""PNG and JPEG images decoded only after their header is checked: one home for the flight
folders (:func:`vp_recon.flight.read_flight`) and the fleet's ``sensor_msgs/CompressedImage``
(:func:`vp_scene.messages.compressed_image_array`).

* The size is read from the header (Pillow's PNG and JPEG plugins read the header only) and an
  image of more than :data:`MAX_IMAGE_PIXELS` pixels is refused before anything is decoded (a
  30000 x 30000 PNG is 2.6 MB on disk and 2.7 GB decoded).
* A truncated or corrupt image is refused: a PNG's chunks are checked against their CRCs
  (Pillow's ``verify``, without decoding); a JPEG or PNG that OpenCV cannot decode to its end is
  refused (``cv2.imdecode`` of a buffer fails on a truncated JPEG where ``cv2.imread`` of the file
  fills the missing rows with grey and returns the image).
* The pixels are OpenCV's (``cv2.imdecode``, ``IMREAD_COLOR``: EXIF orientation applied, 16 bits
  scaled to 8), as they always were, returned as RGB.

Every problem is an :class:`ImageError` (a ValueError) of one line that starts with ``what``
(the file, the message). ROS-free: numpy, OpenCV, Pillow.
"""
from __future__ import annotations

import io
import os
from pathlib import Path
from typing import BinaryIO, Union

import numpy as np
from numpy.typing import NDArray

__all__ = ["MAX_IMAGE_PIXELS", "ImageError", "image_size", "decode_image", "read_image"]

#: Pixels an image may have (width x height): 150 MP, room for the largest aerial survey
#: cameras (100 MP); decoded as RGB that is 450 MB.
MAX_IMAGE_PIXELS = 150_000_000
#: A file may hold at most this many bytes a pixel of its header's size, plus 16 MiB of
#: metadata (a 16-bit RGBA PNG stored without compression is 8): a small image in a huge file
#: is refused before the file is read.
_MAX_FILE_BYTES_PER_PIXEL = 8
_FILE_SLACK = 16 << 20

_PNG = b"\x89PNG\r\n\x1a\n"
_JPEG = b"\xff\xd8\xff"


class ImageError(ValueError):
    """An image that is not read: not a PNG or JPEG, too large, truncated or corrupt."""


def _plugin(head: bytes):
    """Pillow's image class of the format of these first bytes (None: neither PNG nor JPEG).
    The plugin classes, not ``PIL.Image.open``: Image.open applies Pillow's own process-wide
    decompression-bomb limit (a warning above 89 MP, an error above 179 MP) before the size can
    be seen, where the suite applies its own limit with its own message."""
    from PIL import JpegImagePlugin, PngImagePlugin

    if head.startswith(_PNG):
        return PngImagePlugin.PngImageFile
    if head.startswith(_JPEG):
        return JpegImagePlugin.JpegImageFile
    return None


def _header(fp: BinaryIO, what: str, max_pixels: int):
    """Pillow's image of ``fp`` with its header read (nothing decoded); ImageError: not a PNG or
    JPEG, a corrupt header, more than ``max_pixels``."""
    start = fp.tell()
    cls = _plugin(fp.read(8))
    fp.seek(start)
    if cls is None:
        raise ImageError(f"{what}: does not decode (corrupt, or not a PNG or JPEG)")
    try:
        im = cls(fp)
    except (OSError, SyntaxError, ValueError, EOFError) as exc:  # Pillow's ways of saying corrupt
        raise ImageError(f"{what}: corrupt {cls.format} header ({' '.join(str(exc).split())})") from None
    w, h = im.size
    if w * h > max_pixels:
        raise ImageError(f"{what}: {w}x{h} pixels ({w * h / 1e6:.0f} MP); an image may have at most "
                         f"{max_pixels / 1e6:g} MP")
    return im


def image_size(fp: BinaryIO, what: str, max_pixels: int = MAX_IMAGE_PIXELS) -> tuple[str, int, int]:
    """(format ``'PNG'`` or ``'JPEG'``, width, height) from the header of the image in ``fp``
    (read from its current position; the header only). ImageError: not a PNG or JPEG, a corrupt
    header, more than ``max_pixels``."""
    im = _header(fp, what, max_pixels)
    return im.format, int(im.size[0]), int(im.size[1])


def decode_image(data: Union[bytes, bytearray, memoryview], what: str,
                 max_pixels: int = MAX_IMAGE_PIXELS) -> NDArray[np.uint8]:
    """RGB (H, W, 3) uint8 of a PNG or JPEG in ``data``: its header checked first
    (:func:`image_size`), a PNG's chunks against their CRCs, then decoded by OpenCV; ImageError
    naming ``what`` for one that is truncated or does not decode to its end."""
    import cv2

    im = _header(io.BytesIO(data), what, max_pixels)
    fmt, (w, h) = im.format, im.size
    if fmt == "PNG":
        try:
            im.verify()  # every chunk's CRC, to IEND: a truncated or damaged PNG, without decoding it
        except (OSError, SyntaxError, ValueError, EOFError) as exc:
            raise ImageError(f"{what}: corrupt or truncated PNG ({' '.join(str(exc).split())})") from None
    a = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_COLOR)
    if a is None:
        raise ImageError(f"{what}: corrupt or truncated {fmt} ({w}x{h} pixels; it does not decode)")
    return np.ascontiguousarray(a[..., ::-1])


def read_image(path: Union[str, os.PathLike], max_pixels: int = MAX_IMAGE_PIXELS) -> NDArray[np.uint8]:
    """RGB (H, W, 3) uint8 of a PNG or JPEG file: its header checked before the file is read in
    full (:func:`image_size`; a file far larger than its pixels is refused too), then decoded
    (:func:`decode_image`). ImageError naming the file."""
    p = Path(path)
    try:
        with open(p, "rb") as f:
            _, w, h = image_size(f, str(p), max_pixels)
            size = os.fstat(f.fileno()).st_size
            if size > _MAX_FILE_BYTES_PER_PIXEL * w * h + _FILE_SLACK:
                raise ImageError(f"{p}: {size} bytes for {w}x{h} pixels (at most "
                                 f"{_MAX_FILE_BYTES_PER_PIXEL} bytes a pixel and 16 MiB more)")
            f.seek(0)
            data = f.read()
    except OSError as exc:
        raise ImageError(f"{p}: cannot read: {exc.strerror or exc}") from None
    return decode_image(data, str(p), max_pixels)
