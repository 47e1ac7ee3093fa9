"""Image decoding, encoding and drawing shared by the detector service and the gateway.

Images travel as bytes plus `encoding`, `width` and `height` (the oricf.v1.Image message,
or a ROS sensor_msgs/Image). Decoding validates everything a caller can get wrong and
raises InvalidInput with a message a person understands; it never crashes on bad bytes.
Internally images are BGR uint8 arrays (OpenCV's order, and YOLOX's input order). OpenCV
is imported by the functions that use it, so that what only names images (the gateway's
pipeline schema) loads no OpenCV.
"""

from __future__ import annotations

import re
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from oricf.errors import InvalidInput
from oricf.logs import quoted

RAW_CHANNELS = {"rgb8": 3, "bgr8": 3, "mono8": 1}
ENCODED = ("jpeg", "png")
ENCODINGS = (*ENCODED, *RAW_CHANNELS)
# Larger than any camera a robot carries (8K is 33 Mpx); refuses absurd sizes before allocating.
MAX_PIXELS = 40_000_000
# Decoding needs the result and its own buffers (see decoded_bytes).
DECODE_WORK_FACTOR = 2


@dataclass(frozen=True)
class Box:
    x_min: float
    y_min: float
    x_max: float
    y_max: float


@dataclass(frozen=True)
class Detection:
    """One object found in an image. The track fields are set by the gateway's `track`
    step and stay None for a detection that no tracker has seen."""
    label: str
    class_id: int
    score: float
    box: Box
    # Stable across frames while the tracker follows the same object.
    track_id: int | None = None
    # Motion of the box centre in pixels per second (x right, y down).
    velocity: tuple[float, float] | None = None


def label_counts(detections: Iterable[Detection], labels: Iterable[str] = ()) -> dict[str, int]:
    """Detections per label; each of `labels` is present, at 0 when none was found.

    The one way detections are counted: the gateway's post-processing steps count with this
    (a model service returns detections, never counts), so counts agree with the detections.
    """
    counts = dict.fromkeys(labels, 0)
    counts.update(Counter(d.label for d in detections))
    return counts


def check_size(width: int, height: int, max_pixels: int = MAX_PIXELS) -> None:
    """Refuses zero, negative and absurd image sizes before anything is allocated."""
    if width <= 0 or height <= 0:
        raise InvalidInput(f"image size {width}x{height}: width and height must be > 0")
    if width * height > max_pixels:
        raise InvalidInput(
            f"image size {width}x{height} is over the limit of {max_pixels:,} pixels")


def image_size(data: bytes, encoding: str, width: int = 0, height: int = 0,
               max_pixels: int = MAX_PIXELS) -> tuple[int, int]:
    """(width, height) the decoded image will have, with everything that can be checked
    before decoding checked: encoding, raw length, the file's header, size, scans."""
    encoding = _encoding_name(encoding)
    if not data:
        raise InvalidInput("image data is empty")
    if encoding in RAW_CHANNELS:
        check_size(width, height, max_pixels)
        channels = RAW_CHANNELS[encoding]
        expected = width * height * channels
        if len(data) != expected:
            raise InvalidInput(
                f"{encoding} image {width}x{height} needs {expected:,} bytes "
                f"({width}x{height}x{channels}), got {len(data):,}")
        return width, height
    # The size comes from the file's own header, before anything is decoded: a few bytes
    # must never make the decoder allocate gigabytes.
    kind, actual_w, actual_h, short = _encoded(data)
    if kind != encoding:
        raise InvalidInput(f"image labelled {encoding} is a {kind.upper()} file")
    check_size(actual_w, actual_h, max_pixels)
    if short:  # the decoder would fill the rest of the image in with grey
        raise InvalidInput(short)
    if (width and width != actual_w) or (height and height != actual_h):
        raise InvalidInput(
            f"image declared as {width}x{height} but the {encoding.upper()} is "
            f"{actual_w}x{actual_h}")
    return actual_w, actual_h


def decoded_bytes(width: int, height: int) -> int:
    """The memory decoding an image of this size may take, for a budget: the BGR result
    and the decoder's own working memory (a progressive JPEG keeps every coefficient until
    its last scan)."""
    return width * height * 3 * DECODE_WORK_FACTOR


def decode_image(data: bytes, encoding: str, width: int = 0, height: int = 0,
                 max_pixels: int = MAX_PIXELS) -> np.ndarray:
    """Bytes -> BGR uint8 array of shape (height, width, 3).

    EXIF orientation is not applied: the array is the stored pixel grid, the one the
    header's size describes, so boxes found in it are in the grid the caller sent."""
    encoding = _encoding_name(encoding)
    width, height = image_size(data, encoding, width, height, max_pixels)
    if encoding in RAW_CHANNELS:
        return _convert_raw(data, encoding, width, height)
    import cv2

    image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8),
                         cv2.IMREAD_COLOR | cv2.IMREAD_IGNORE_ORIENTATION)
    if image is None or image.shape[:2] != (height, width):
        raise InvalidInput(f"image data is not a valid {encoding.upper()} file")
    return image


def _encoding_name(encoding: str) -> str:
    encoding = encoding.lower()
    if encoding == "jpg":
        encoding = "jpeg"
    if encoding not in ENCODINGS:
        raise InvalidInput(
            f"unknown image encoding {quoted(encoding)}; use one of: {', '.join(ENCODINGS)}")
    return encoding


def _convert_raw(data: bytes, encoding: str, width: int, height: int) -> np.ndarray:
    import cv2

    pixels = np.frombuffer(data, dtype=np.uint8).reshape(height, width, RAW_CHANNELS[encoding])
    if encoding == "rgb8":
        return cv2.cvtColor(pixels, cv2.COLOR_RGB2BGR)
    if encoding == "mono8":
        return cv2.cvtColor(pixels, cv2.COLOR_GRAY2BGR)
    return pixels


PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
# Every JPEG start-of-frame marker (baseline, progressive, lossless, arithmetic...): C0-CF
# except DHT (C4), JPG (C8) and DAC (CC), which are not frames.
JPEG_FRAMES = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}
# Markers without a length field: RST0-7 and TEM.
JPEG_STANDALONE = frozenset(range(0xD0, 0xD8)) | {0x01}
# In entropy-coded data 0xFF is followed by 0x00 (a stuffed byte) or a restart marker; any
# other byte after it (but 0xFF, a fill byte) is the next marker.
JPEG_NEXT_MARKER = re.compile(rb"\xff[^\x00\xd0-\xd7\xff]")
# Huffman-coded DCT frames (baseline, extended, progressive): every scan that carries DC
# coefficients codes each of its blocks with at least one bit, so its data bounds the size.
JPEG_HUFFMAN_DCT = frozenset({0xC0, 0xC1, 0xC2})
# Decoders pass over the whole image once per scan, so repeating scans multiplies the CPU a
# small file costs. Encoders write far fewer (libjpeg's progressive script: 10 for colour,
# 18 for CMYK).
MAX_JPEG_SCANS = 64


@dataclass(frozen=True)
class JpegFrame:
    """A JPEG's frame header (SOFn)."""

    marker: int
    width: int
    height: int
    sampling: dict[int, tuple[int, int]]  # component id -> (horizontal, vertical) factors
    end: int  # where the segment after it starts

    def blocks(self, components: list[int]) -> int:
        """The 8x8 blocks a scan of these components codes (an interleaved scan codes whole
        MCUs); 0 where the header does not say (the decoder refuses such a file)."""
        factors = [self.sampling.get(c, (0, 0)) for c in components]
        if not factors or not self.sampling or min(min(f) for f in factors) == 0:
            return 0
        h_max = max(h for h, _ in self.sampling.values())
        v_max = max(v for _, v in self.sampling.values())
        if len(factors) == 1:  # the component's own samples, in blocks
            h, v = factors[0]
            return (_ceil(_ceil(self.width * h, h_max), 8)
                    * _ceil(_ceil(self.height * v, v_max), 8))
        mcus = _ceil(self.width, 8 * h_max) * _ceil(self.height, 8 * v_max)
        return mcus * sum(h * v for h, v in factors)


def _ceil(a: int, b: int) -> int:
    return -(-a // b)


def encoded_size(data: bytes) -> tuple[str, int, int]:
    """("jpeg" or "png", width, height) from the file's header, whatever it is labelled;
    raises InvalidInput for anything else, a header that cannot be read, or a JPEG with
    more than MAX_JPEG_SCANS scans."""
    kind, width, height, _ = _encoded(data)
    return kind, width, height


def _encoded(data: bytes) -> tuple[str, int, int, str]:
    """encoded_size's answer, and why a JPEG's data is too short for its frame ("" if it
    is not)."""
    if data.startswith(PNG_SIGNATURE):
        if len(data) < 24 or data[12:16] != b"IHDR":
            raise InvalidInput("PNG file without its IHDR header (corrupt or truncated)")
        return ("png", int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big"),
                "")
    if data.startswith(b"\xff\xd8"):
        frame = _jpeg_frame(data)
        return "jpeg", frame.width, frame.height, _walk_jpeg_scans(data, frame)
    raise InvalidInput("image data is neither a JPEG nor a PNG file")


def _jpeg_frame(data: bytes) -> JpegFrame:
    """Walks the JPEG's marker segments to its frame header (SOFn)."""
    i, end = 2, len(data)
    while i < end:
        if data[i] != 0xFF:
            break
        while i < end and data[i] == 0xFF:  # any number of 0xFF fill bytes before a marker
            i += 1
        if i >= end:
            break
        marker = data[i]
        i += 1
        if marker in JPEG_STANDALONE:
            continue
        if marker in (0xD9, 0xDA):  # end of image, or image data, before any frame header
            raise InvalidInput("JPEG file has no frame header before its image data")
        if i + 2 > end:
            break
        length = int.from_bytes(data[i:i + 2], "big")
        if length < 2:
            break
        if marker in JPEG_FRAMES:
            if i + 7 > end:
                break
            components = data[i + 8:min(i + length, end)]
            sampling = {components[k]: (components[k + 1] >> 4, components[k + 1] & 15)
                        for k in range(0, len(components) - 2, 3)}
            return JpegFrame(marker, int.from_bytes(data[i + 5:i + 7], "big"),
                             int.from_bytes(data[i + 3:i + 5], "big"), sampling, i + length)
        i += length
    raise InvalidInput("JPEG file is corrupt or truncated before its frame header")


def _walk_jpeg_scans(data: bytes, frame: JpegFrame) -> str:
    """Walks the scans (SOS segments) after the frame header to the end of the image,
    refusing more than MAX_JPEG_SCANS, and says why a scan's data is too short for the
    frame ("" if none is). Segments are skipped by their length, so a thumbnail inside EXIF
    does not count; entropy-coded data is searched for the next marker."""
    scans, end, i = 0, len(data), frame.end
    scan: tuple[int, int] | None = None  # the open scan: where its data starts, bits it needs
    while True:
        found = JPEG_NEXT_MARKER.search(data, i)
        if scan is not None:  # its data runs to this marker (or to the end of the file)
            held = (found.start() if found else end) - scan[0]
            if held * 8 < scan[1]:
                return (f"JPEG scan {scans} holds {held:,} bytes, too few for the "
                        f"{frame.width}x{frame.height} image its frame header claims (at "
                        f"least {_ceil(scan[1], 8):,}): corrupt, truncated or lying about "
                        f"its size")
            scan = None
        if found is None:
            break
        marker = data[found.start() + 1]
        i = found.start() + 2
        if marker == 0xD9:  # end of image: what follows is not decoded
            break
        if marker in JPEG_STANDALONE:
            continue
        if i + 2 > end:
            break
        length = int.from_bytes(data[i:i + 2], "big")
        if length < 2:
            break  # corrupt: the decoder refuses it
        if marker == 0xDA:
            scans += 1
            if scans > MAX_JPEG_SCANS:
                raise InvalidInput(
                    f"JPEG file has more than {MAX_JPEG_SCANS} scans; refused because every "
                    f"scan is another pass over the whole image")
            scan = (i + length, _scan_bits(data[i + 2:i + length], frame))
        i += length
    return ""


def _scan_bits(header: bytes, frame: JpegFrame) -> int:
    """The fewest bits a scan's data can hold: one per block it codes where it carries DC
    coefficients (a Huffman code is at least one bit; a DC refinement is one bit), none for
    an AC scan of a progressive JPEG (one code may end thousands of blocks) or arithmetic
    coding."""
    count = header[0] if header else 0
    if frame.marker not in JPEG_HUFFMAN_DCT or len(header) < 2 + 2 * count:
        return 0
    spectral_start = header[1 + 2 * count]
    if spectral_start != 0:
        return 0
    return frame.blocks([header[1 + 2 * k] for k in range(count)])


def encode_image(image: np.ndarray, encoding: str, jpeg_quality: int = 85) -> bytes:
    """BGR array -> bytes in the given encoding."""
    import cv2

    if encoding in ENCODED:
        ext = ".jpg" if encoding == "jpeg" else ".png"
        params = [cv2.IMWRITE_JPEG_QUALITY, jpeg_quality] if encoding == "jpeg" else []
        ok, buffer = cv2.imencode(ext, image, params)
        if not ok:
            raise InvalidInput(f"could not encode the image as {encoding}")
        return buffer.tobytes()
    if encoding == "bgr8":
        return np.ascontiguousarray(image).tobytes()
    if encoding == "rgb8":
        return cv2.cvtColor(image, cv2.COLOR_BGR2RGB).tobytes()
    if encoding == "mono8":
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY).tobytes()
    raise InvalidInput(f"unknown image encoding {quoted(encoding)}; "
                       f"use one of: {', '.join(ENCODINGS)}")


def draw_detections(image: np.ndarray, detections: Iterable[Detection]) -> np.ndarray:
    """A copy of the image with a labelled box per detection."""
    import cv2

    canvas = image.copy()
    for det in detections:
        p1 = (round(det.box.x_min), round(det.box.y_min))
        p2 = (round(det.box.x_max), round(det.box.y_max))
        cv2.rectangle(canvas, p1, p2, (0, 200, 0), 2)
        caption = f"{det.label} {det.score:.2f}"
        cv2.putText(canvas, caption, (p1[0], max(p1[1] - 4, 12)), cv2.FONT_HERSHEY_SIMPLEX,
                    0.5, (0, 200, 0), 1, cv2.LINE_AA)
    return canvas
