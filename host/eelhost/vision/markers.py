"""The robot's printed markers: which ArUco marker goes on which link, how big, and where.

Layout (the default, for the 6-link paper robot)
-------------------------------------------------
- Dictionary ``DICT_4X4_50`` (a standard OpenCV dictionary, so any ArUco generator prints the same
  pattern): 4 x 4 data bits inside a one-cell black border, 6 x 6 cells in all.
- Link i (1 = tail ... 6 = head) carries marker id i - 1.
- Black square 0.060 m a side (0.010 m cells), on a white plate with a 0.005 m quiet zone each side
  (plate 0.070 m). At the paper camera's 3.8 mm per pixel the black square spans about 16 px; that is
  about the smallest the detector reads reliably through blur, noise and JPEG, and 0.070 m plates on
  0.107 m links stay clear of each other up to a joint angle of about 1 rad (the twin's runs reach
  0.99 rad).
- Each plate is mounted flat, above the water, with the marker's centre over the link's centre
  (``offsets_m`` = 0; a non-zero offset moves it along the link, positive towards the head) and
  the **right-hand edge of the printed marker facing the head**. The link angle is then the
  direction of the marker's top edge, left to right, as seen from above.

The printed size does not enter the localisation (the calibration homography maps pixels to
metres and only the marker's centre and orientation are used), so a sheet printed at 97 % scale
still works; the size only matters for the plates' clearance.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import NDArray

from eelhost.errors import UserError

INCH_M = 0.0254


class MarkerLayoutError(UserError, ValueError):
    """A marker layout or sheet that cannot be made (ids, sizes, dictionary, file type)."""


@dataclass(frozen=True)
class MarkerLayout:
    """Which marker is on which link, and its geometry.

    Attributes
    ----------
    dictionary_name : str
        Name of a predefined OpenCV ArUco dictionary (``cv2.aruco.DICT_...``).
    link_ids : tuple of int
        Marker id on each link, tail (link 1) first.
    marker_size_m : float
        Side of the black square.
    margin_m : float
        White quiet zone around the black square, each side.
    offsets_m : tuple of float
        Marker centre minus link centre, along the link axis (positive towards the head); one per
        link, or empty for all zero.
    """

    dictionary_name: str = "DICT_4X4_50"
    link_ids: tuple[int, ...] = (0, 1, 2, 3, 4, 5)
    marker_size_m: float = 0.060
    margin_m: float = 0.005
    offsets_m: tuple[float, ...] = field(default_factory=tuple)

    def __post_init__(self) -> None:
        if not hasattr(cv2.aruco, self.dictionary_name):
            raise MarkerLayoutError(f"unknown ArUco dictionary {self.dictionary_name!r}")
        if len(set(self.link_ids)) != len(self.link_ids):
            raise MarkerLayoutError(f"marker ids must be distinct, got {self.link_ids}")
        size = self.dictionary().bytesList.shape[0]
        if any(not 0 <= i < size for i in self.link_ids):
            raise MarkerLayoutError(f"marker ids must be in 0..{size - 1} for {self.dictionary_name}")
        if self.offsets_m and len(self.offsets_m) != len(self.link_ids):
            raise MarkerLayoutError("offsets_m needs one value per link (or none)")
        if not (self.marker_size_m > 0 and self.margin_m >= 0):
            raise MarkerLayoutError("marker size must be positive and the margin non-negative")

    @property
    def n_links(self) -> int:
        """Number of links carrying a marker."""
        return len(self.link_ids)

    @property
    def plate_size_m(self) -> float:
        """Side of the white plate (marker plus quiet zone)."""
        return self.marker_size_m + 2.0 * self.margin_m

    @property
    def cells(self) -> int:
        """Cells across the black square (data bits plus the one-cell border each side)."""
        return int(self.dictionary().markerSize) + 2

    def offsets(self) -> NDArray[np.float64]:
        """Marker offsets along each link, shape (N,)."""
        if not self.offsets_m:
            return np.zeros(self.n_links)
        return np.asarray(self.offsets_m, dtype=float)

    def dictionary(self) -> cv2.aruco.Dictionary:
        """The OpenCV dictionary object."""
        return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary_name))

    def link_of(self, marker_id: int) -> int | None:
        """Index (0 = tail) of the link carrying ``marker_id``, or None for a foreign marker."""
        try:
            return self.link_ids.index(int(marker_id))
        except ValueError:
            return None


def default_layout(n_links: int = 6) -> MarkerLayout:
    """The default layout for an ``n_links`` robot: ids 0..N-1, tail first."""
    return MarkerLayout(link_ids=tuple(range(n_links)))


def plate_image(layout: MarkerLayout, link_index: int, px_per_cell: int) -> NDArray[np.uint8]:
    """The plate of one link (marker plus white quiet zone) as a grey image.

    Parameters
    ----------
    layout : MarkerLayout
        The marker layout.
    link_index : int
        0 = tail.
    px_per_cell : int
        Pixels per marker cell; the quiet zone is scaled to match.

    Returns
    -------
    ndarray, uint8, square
        Black 0, white 255; the printed marker's right-hand edge is the head side.
    """
    cells = layout.cells
    marker = cv2.aruco.generateImageMarker(
        layout.dictionary(), layout.link_ids[link_index], cells * px_per_cell, borderBits=1
    )
    margin_px = int(round(layout.margin_m / layout.marker_size_m * cells * px_per_cell))
    framed = cv2.copyMakeBorder(
        marker, margin_px, margin_px, margin_px, margin_px, cv2.BORDER_CONSTANT, value=255
    )
    return np.asarray(framed, dtype=np.uint8)


def marker_sheet(
    layout: MarkerLayout, dpi: float = 300.0, paper_m: tuple[float, float] = (0.210, 0.297)
) -> tuple[NDArray[np.uint8], float]:
    """A printable sheet with every link's plate at true size, labelled, with cut lines.

    Parameters
    ----------
    layout : MarkerLayout
        The marker layout.
    dpi : float
        Printer resolution, dots per inch.
    paper_m : (float, float)
        Paper width and height (A4 portrait by default).

    Returns
    -------
    image : ndarray, uint8, (H, W)
        The sheet.
    printed_marker_m : float
        The black square's side as it will print (cells are a whole number of dots, so it
        differs from ``layout.marker_size_m`` by less than a dot per cell).

    Raises
    ------
    ValueError
        If the plates do not fit on the paper.
    """
    dots_per_m = dpi / INCH_M
    cell_m = layout.marker_size_m / layout.cells
    px_per_cell = max(1, int(round(cell_m * dots_per_m)))
    width_px, height_px = (int(round(v * dots_per_m)) for v in paper_m)
    sheet = np.full((height_px, width_px), 255, np.uint8)
    plates = [plate_image(layout, i, px_per_cell) for i in range(layout.n_links)]
    side = plates[0].shape[0]
    gap = int(round(0.018 * dots_per_m))  # room for a label and scissors between plates
    top = int(1.5 * gap)
    cols = max(1, (width_px - gap) // (side + gap))
    rows = -(-layout.n_links // cols)
    if cols * (side + gap) + gap > width_px or rows * (side + gap) + top > height_px:
        raise MarkerLayoutError(f"{layout.n_links} plates of {layout.plate_size_m} m do not fit on "
                         f"{paper_m[0]} x {paper_m[1]} m paper")
    scale = dpi / 300.0
    font = cv2.FONT_HERSHEY_SIMPLEX
    title = (f"eelbot markers {layout.dictionary_name}, black square "
             f"{px_per_cell * layout.cells / dots_per_m * 1000:.1f} mm; right edge faces the head")
    cv2.putText(sheet, title, (gap, int(0.8 * gap)), font, 1.1 * scale, 0, max(1, int(2 * scale)))
    for i, plate in enumerate(plates):
        r, c = divmod(i, cols)
        x0 = gap + c * (side + gap)
        y0 = top + r * (side + gap)
        sheet[y0 : y0 + side, x0 : x0 + side] = plate
        # Thin grey cut line just outside the plate so the quiet zone survives the scissors.
        cv2.rectangle(sheet, (x0 - 2, y0 - 2), (x0 + side + 1, y0 + side + 1), 160, 1)
        name = "tail" if i == 0 else "head" if i == layout.n_links - 1 else "body"
        label = f"link {i + 1} ({name}) id {layout.link_ids[i]}  head ->"
        cv2.putText(sheet, label, (x0, y0 + side + int(gap * 0.6)), font, 1.4 * scale, 0,
                    max(1, int(3 * scale)))
    return sheet, px_per_cell * layout.cells / dots_per_m


def save_marker_sheet(path: str | Path, layout: MarkerLayout, dpi: float = 300.0) -> Path:
    """Write the marker sheet as PNG or PDF (chosen by the suffix), tagged with its DPI.

    Print it at 100 % ("actual size", no fit-to-page).

    Parameters
    ----------
    path : str or Path
        Output file, ``.png`` or ``.pdf``.
    layout : MarkerLayout
        The marker layout.
    dpi : float
        Resolution.

    Returns
    -------
    Path
        The file written.
    """
    from PIL import Image  # Pillow comes with matplotlib; only the sheet writer needs it

    out = Path(path)
    suffix = out.suffix.lower()
    if suffix not in (".png", ".pdf"):
        raise MarkerLayoutError(f"{out}: marker sheet must be .png or .pdf")
    sheet, _ = marker_sheet(layout, dpi)
    out.parent.mkdir(parents=True, exist_ok=True)
    image = Image.fromarray(sheet)
    if suffix == ".pdf":
        image.save(out, "PDF", resolution=dpi)
    else:
        image.save(out, "PNG", dpi=(dpi, dpi))
    return out
