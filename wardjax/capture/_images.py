"""A capture's images as sources of rows: a band decoded on demand, never the whole image.

A 50 MP 16-bit RGB image is 300 MB of codes and 600 MB as float32; a fit
needs only the standard's crop and a band of the probe's rows at a time. A
TIFF is read in bands: an uncompressed one with its pixels in one block
(what :func:`wardjax.simulate_capture` and most raw converters write) by
plain positioned reads of the rows asked for; a compressed or tiled one
segment by segment (strips or tiles, each decoded by tifffile's own codec
for that segment, :attr:`tifffile.TiffPage.decode`), only the segments that
overlap the window. PNG and JPEG cannot be read in bands cheaply (one
compressed stream), nor can raw files or TIFF layouts other than one page
of 1, 3 or 4 interleaved samples: those are decoded whole at load, and held
as codes (2 bytes a value at 16 bits, not float32).

Codes are what the file stores (uint8/uint16, grey repeated over RGB, alpha
dropped: :func:`~wardjax._files.as_rgb`); :class:`CaptureImages` turns a
window of them into linear float32 through the encoding's look-up table.
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np

from .._files import as_rgb, read_image

__all__ = ["ArrayImage", "CaptureImages", "ImageSource", "TiffImage", "Window", "open_image"]

_PHOTOMETRIC_OK = (1, 2)  # MINISBLACK, RGB: what tifffile.imread returns as stored values
_STATS_ROWS = 512  # rows per read when an image is scanned whole (load-time checks, materialising)


class ImageSource:
    """An image file's codes, readable by windows of rows and columns.

    Attributes
    ----------
    name
        The file's name (as ``capture.toml`` gives it).
    height, width
        Size in pixels.
    channels
        Channels as stored (1 grey, 3 RGB, 4 RGBA).
    dtype
        The stored dtype (native byte order).
    banded
        ``True`` when a window decodes only the rows (segments) it needs;
        ``False`` when the whole image was decoded at load.
    decoded_pixels, largest_read
        Pixels decoded so far, and the most decoded by one call (segments are
        decoded whole, so a read can decode a little more than its window).
    """

    name: str
    height: int
    width: int
    channels: int
    dtype: np.dtype
    banded: bool = False

    def __init__(self) -> None:
        self.decoded_pixels = 0
        self.largest_read = 0

    def _count(self, pixels: int) -> None:
        self.decoded_pixels += pixels
        self.largest_read = max(self.largest_read, pixels)

    def read(self, rows: slice, cols: slice = slice(None)) -> np.ndarray:
        """The codes of ``rows × cols`` as ``(n, m, 3)`` (grey repeated over RGB, alpha dropped)."""
        raise NotImplementedError

    def extremes(self) -> tuple[int, int]:
        """The smallest and largest code over the whole image, read band by band."""
        lo, hi = None, None
        for r0 in range(0, self.height, _STATS_ROWS):
            codes = self.read(slice(r0, min(r0 + _STATS_ROWS, self.height)))
            a, b = int(codes.min()), int(codes.max())
            lo, hi = (a, b) if lo is None or hi is None else (min(lo, a), max(hi, b))
        if lo is None or hi is None:
            raise ValueError("the image holds no pixel")
        return lo, hi


class ArrayImage(ImageSource):
    """An image decoded whole when opened (PNG, JPEG, raw, unusual TIFF layouts): windows are slices of it."""

    def __init__(self, name: str, stored: np.ndarray) -> None:
        super().__init__()
        self.name = name
        self.channels = 1 if stored.ndim == 2 else int(stored.shape[-1])
        self.codes = as_rgb(stored)
        self.height, self.width = (int(n) for n in self.codes.shape[:2])
        self.dtype = self.codes.dtype
        self._count(self.height * self.width)

    def read(self, rows: slice, cols: slice = slice(None)) -> np.ndarray:
        return self.codes[rows, cols]

    def extremes(self) -> tuple[int, int]:
        if self.codes.size == 0:
            raise ValueError("the image holds no pixel")
        return int(self.codes.min()), int(self.codes.max())


class TiffImage(ImageSource):
    """A one-page TIFF read by windows: positioned reads of contiguous rows, else the overlapping segments.

    The file is opened for each read (no handle is held between reads: a
    capture can be pickled, and nothing is left open when it is dropped).
    """

    banded = True

    def __init__(self, path: Path, name: str, tif) -> None:
        super().__init__()
        page = tif.pages[0]
        self.path, self.name = path, name
        self.height, self.width = (int(n) for n in page.shape[:2])
        self.channels = 1 if len(page.shape) == 2 else int(page.shape[2])
        self.dtype = np.dtype(page.dtype)
        self._stored = self.dtype.newbyteorder(tif.byteorder)
        self._chunks = (int(page.chunks[0]), int(page.chunks[1]))
        self._chunked = (int(page.chunked[0]), int(page.chunked[1]))
        row_bytes = self.width * self.channels * self.dtype.itemsize
        self._row_bytes = row_bytes
        contiguous = (
            page.compression == 1
            and page.fillorder == 1
            and not page.is_tiled
            and bool(page.is_contiguous)
            and int(sum(page.databytecounts)) >= self.height * row_bytes
        )
        self._offset = int(page.dataoffsets[0]) if contiguous else None

    def read(self, rows: slice, cols: slice = slice(None)) -> np.ndarray:
        r0, r1, _ = rows.indices(self.height)
        c0, c1, _ = cols.indices(self.width)
        r1, c1 = max(r1, r0), max(c1, c0)
        if self._offset is not None:
            out = self._read_rows(r0, r1)[:, c0:c1]
        else:
            out = self._read_segments(r0, r1, c0, c1)
        return as_rgb(out)

    def _read_rows(self, r0: int, r1: int) -> np.ndarray:
        n = (r1 - r0) * self._row_bytes
        assert self._offset is not None
        with open(self.path, "rb") as fh:
            fh.seek(self._offset + r0 * self._row_bytes)
            data = fh.read(n)
        if len(data) != n:
            raise ValueError(f"the file ends {n - len(data)} bytes short of row {r1}")
        self._count((r1 - r0) * self.width)
        codes = np.frombuffer(data, self._stored).reshape(r1 - r0, self.width, self.channels)
        return codes.astype(self.dtype)  # native byte order, writable

    def _read_segments(self, r0: int, r1: int, c0: int, c1: int) -> np.ndarray:
        import tifffile

        (ch_r, ch_c), (_, per_row) = self._chunks, self._chunked
        out = np.zeros((r1 - r0, c1 - c0, self.channels), self.dtype)  # a missing segment reads as 0, as imread
        if r1 == r0 or c1 == c0:
            return out
        decoded = 0
        with tifffile.TiffFile(self.path) as tif:
            page, fh = tif.pages[0], tif.filehandle
            decode = page.decode
            for i in range(r0 // ch_r, (r1 - 1) // ch_r + 1):
                for j in range(c0 // ch_c, (c1 - 1) // ch_c + 1):
                    index = i * per_row + j
                    offset, count = int(page.dataoffsets[index]), int(page.databytecounts[index])
                    if count == 0:
                        continue
                    fh.seek(offset)
                    data = fh.read(count)
                    if len(data) != count:
                        raise ValueError(f"the file ends {count - len(data)} bytes short of segment {index}")
                    seg, _, _ = decode(data, index, jpegtables=page.jpegtables)  # pyright: ignore[reportCallIssue]
                    if seg is None:
                        continue
                    block: np.ndarray = np.asarray(seg)
                    block = block.reshape(block.shape[-3:])  # (1, rows, cols, samples) as decoded
                    n_r, n_c = int(block.shape[0]), int(block.shape[1])
                    decoded += n_r * n_c
                    # the segment covers image rows i·ch_r …, columns j·ch_c … (a tile may pass the edge)
                    a0, b0 = max(r0, i * ch_r), max(c0, j * ch_c)
                    a1, b1 = min(r1, i * ch_r + n_r), min(c1, j * ch_c + n_c)
                    if a1 > a0 and b1 > b0:
                        out[a0 - r0 : a1 - r0, b0 - c0 : b1 - c0] = block[
                            a0 - i * ch_r : a1 - i * ch_r, b0 - j * ch_c : b1 - j * ch_c
                        ]
        self._count(decoded)
        return out


def _tiff_source(path: Path, name: str) -> ImageSource | None:
    """A :class:`TiffImage` when the file is one page tifffile reads as ``(H, W[, 1|3|4])`` uint8/uint16, else ``None``.

    ``None`` (an unusual layout, a header tifffile refuses) sends the file to
    the whole-image reader, which reads what it can or says why it cannot.
    """
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            if len(tif.pages) != 1 or len(tif.series) != 1:
                return None
            page = tif.pages[0]
            if not isinstance(page, tifffile.TiffPage) or page.size != int(np.prod(tif.series[0].shape)):
                return None
            shape, dtype = page.shape, np.dtype(page.dtype) if page.dtype is not None else None
            if dtype not in (np.dtype(np.uint8), np.dtype(np.uint16)) or page.imagedepth != 1:
                return None
            if len(shape) not in (2, 3) or (len(shape) == 3 and (shape[2] not in (1, 3, 4) or page.planarconfig != 1)):
                return None
            if page.photometric not in _PHOTOMETRIC_OK or page.is_subsampled or min(shape[:2]) < 1:
                return None
            if len(page.dataoffsets) != page.chunked[0] * page.chunked[1]:
                return None
            return TiffImage(path, name, tif)
    except Exception:  # the whole-image reader gives the reason
        return None


def open_image(path: Path, name: str) -> ImageSource:
    """The source of one image file: a banded :class:`TiffImage` where the layout allows, else whole.

    Only the header is read for a banded TIFF; an image decoded whole is read
    here. Raises ``OSError`` (the file cannot be opened) or ``ValueError``
    (it cannot be decoded, or is not an image of 1, 3 or 4 channels) with the
    reader's first line.
    """
    if path.suffix.lower() in (".tif", ".tiff"):
        source = _tiff_source(path, name)
        if source is not None:
            return source
    return ArrayImage(name, read_image(path, rgb=False))


class Window(NamedTuple):
    """A window of a capture's images, linear float32 (full scale 1).

    Attributes
    ----------
    lit, dark
        ``(n, m, 3)`` float32; ``dark`` is ``None`` for a capture without one.
    clipped
        ``(n, m, 3)`` bool: the lit value is the largest code.
    """

    lit: np.ndarray
    dark: np.ndarray | None
    clipped: np.ndarray


class CaptureImages(NamedTuple):
    """The lit and dark sources of a capture and how their codes decode.

    Attributes
    ----------
    lit, dark
        The :class:`ImageSource` of each (``dark`` may be ``None``).
    lut
        The linear float32 value of every code (``images.encoding``, ``images.bit_depth``).
    top
        The largest code (a clipped value).
    """

    lit: ImageSource
    dark: ImageSource | None
    lut: np.ndarray
    top: int

    @property
    def banded(self) -> bool:
        """Every image is read by windows (none was decoded whole at load)."""
        return self.lit.banded and (self.dark is None or self.dark.banded)

    def window(self, rows: slice, cols: slice = slice(None)) -> Window:
        """``rows × cols`` of lit and dark decoded to linear float32, and where lit is clipped."""
        codes = self.lit.read(rows, cols)
        dark = None if self.dark is None else self.lut[self.dark.read(rows, cols)]
        return Window(self.lut[codes], dark, codes == self.top)

    def clipped(self, rows: slice, cols: slice = slice(None)) -> np.ndarray:
        """``(n, m, 3)`` bool: where the lit value of ``rows × cols`` is clipped (the codes only, not decoded)."""
        return self.lit.read(rows, cols) == self.top

    def whole(self, which: str) -> np.ndarray:
        """The whole of ``"lit"``, ``"dark"`` (linear float32) or ``"clipped"`` (bool), built band by band."""
        src = self.dark if which == "dark" else self.lit
        if src is None:
            raise ValueError("the capture has no dark image")
        out = np.empty((src.height, src.width, 3), bool if which == "clipped" else np.float32)
        for r0 in range(0, src.height, _STATS_ROWS):
            rows = slice(r0, min(r0 + _STATS_ROWS, src.height))
            codes = src.read(rows)
            out[rows] = codes == self.top if which == "clipped" else self.lut[codes]
        return out
