"""Printable PDFs at true size: the robot's marker sheet and the ChArUco calibration board.

Each marker is embedded as its bit matrix (one image pixel per cell, black 0 and white 255) drawn
without interpolation over exactly its printed extent, so the PDF's geometry is exact to the
printer's resolution: a 60 mm marker is 60 mm on paper when printed at 100 % ("actual size", no
fit to page), and the page is the paper's size (A4 for the sheet; for the board, the smallest ISO A
size that holds it with 10 mm margins). Pages are laid out in millimetres from the top-left corner.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import matplotlib

matplotlib.use("Agg")  # no display: the figures are only written to files
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.axes import Axes  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
from numpy.typing import NDArray  # noqa: E402

from eelhost.files import atomic_writer  # noqa: E402
from eelhost.vision.calibration import CharucoSpec  # noqa: E402
from eelhost.vision.markers import MarkerLayout, MarkerLayoutError  # noqa: E402

__all__ = ["A4_MM", "iso_a_paper_mm", "write_board_pdf", "write_marker_sheet_pdf"]

A4_MM = (210.0, 297.0)
ISO_A_MM = ((210.0, 297.0), (297.0, 420.0), (420.0, 594.0), (594.0, 841.0), (841.0, 1189.0))
MM_PER_INCH = 25.4
GAP_MM = 18.0  # between plates: room for a label and the scissors
CUT_GREY = "0.6"


def iso_a_paper_mm(content_mm: tuple[float, float], margin_mm: float = 10.0) -> tuple[float, float]:
    """The smallest ISO A paper (A4 to A0), portrait or landscape, holding ``content_mm``.

    Parameters
    ----------
    content_mm : (float, float)
        Width and height of what must fit.
    margin_mm : float
        Free border each side.

    Returns
    -------
    (float, float)
        Paper width and height, mm, oriented like the content.

    Raises
    ------
    MarkerLayoutError
        When even A0 is too small.
    """
    w, h = content_mm[0] + 2 * margin_mm, content_mm[1] + 2 * margin_mm
    for short, long_ in ISO_A_MM:
        if max(w, h) <= long_ and min(w, h) <= short:
            return (long_, short) if w > h else (short, long_)
    raise MarkerLayoutError(f"{content_mm[0]:g} x {content_mm[1]:g} mm does not fit on A0")


def marker_bits(dictionary: cv2.aruco.Dictionary, marker_id: int, cells: int) -> NDArray[np.uint8]:
    """A marker as its cell matrix (``cells`` x ``cells``, black border included): 0 or 255."""
    return np.asarray(cv2.aruco.generateImageMarker(dictionary, marker_id, cells, borderBits=1),
                      np.uint8)


def _page(paper_mm: tuple[float, float]) -> tuple[plt.Figure, Axes]:
    fig = plt.figure(figsize=(paper_mm[0] / MM_PER_INCH, paper_mm[1] / MM_PER_INCH))
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_xlim(0.0, paper_mm[0])
    ax.set_ylim(paper_mm[1], 0.0)  # y down the page, like the printed image
    ax.set_axis_off()
    return fig, ax


def _image(ax: Axes, img: NDArray[np.uint8], x_mm: float, y_mm: float, w_mm: float,
           h_mm: float) -> None:
    # extent (left, right, bottom, top) with the y axis pointing down the page
    ax.imshow(img, cmap="gray", vmin=0, vmax=255, interpolation="none",
              extent=(x_mm, x_mm + w_mm, y_mm + h_mm, y_mm), aspect="auto")


def _save(fig: plt.Figure, path: str | Path) -> Path:
    out = Path(path)
    if out.suffix.lower() != ".pdf":
        raise MarkerLayoutError(f"{out}: the printable file must be a .pdf")
    try:
        with atomic_writer(out, "wb") as f:  # whole or not at all (eelhost.files)
            fig.savefig(f, format="pdf")
    finally:
        plt.close(fig)
    return out


def plate_positions_mm(layout: MarkerLayout, paper_mm: tuple[float, float] = A4_MM
                       ) -> list[tuple[float, float]]:
    """Top-left corner of each link's plate on the sheet, mm (link 1 first).

    Raises
    ------
    MarkerLayoutError
        When the plates do not fit on the paper.
    """
    side = layout.plate_size_m * 1000.0
    top = 1.5 * GAP_MM
    cols = max(1, int((paper_mm[0] - GAP_MM) // (side + GAP_MM)))
    rows = -(-layout.n_links // cols)
    if cols * (side + GAP_MM) + GAP_MM > paper_mm[0] or rows * (side + GAP_MM) + top > paper_mm[1]:
        raise MarkerLayoutError(f"{layout.n_links} plates of {side:g} mm do not fit on "
                                f"{paper_mm[0]:g} x {paper_mm[1]:g} mm paper")
    return [(GAP_MM + (i % cols) * (side + GAP_MM), top + (i // cols) * (side + GAP_MM))
            for i in range(layout.n_links)]


def write_marker_sheet_pdf(path: str | Path, layout: MarkerLayout,
                           paper_mm: tuple[float, float] = A4_MM) -> Path:
    """Write the robot's marker sheet: every link's plate at true size, labelled, with cut lines.

    Parameters
    ----------
    path : str or Path
        The ``.pdf`` to write.
    layout : MarkerLayout
        The markers (their ids, size and quiet zone).
    paper_mm : (float, float)
        Paper width and height (A4 portrait by default).

    Returns
    -------
    Path
        The file written.
    """
    fig, ax = _page(paper_mm)
    marker_mm = layout.marker_size_m * 1000.0
    margin_mm = layout.margin_m * 1000.0
    side = marker_mm + 2 * margin_mm
    ax.text(GAP_MM, 0.8 * GAP_MM,
            f"eelbot markers, {layout.dictionary_name}, black square {marker_mm:g} mm: print at "
            "100 % (actual size); the right-hand edge of each marker faces the head",
            fontsize=8, va="center")
    for i, (x, y) in enumerate(plate_positions_mm(layout, paper_mm)):
        bits = marker_bits(layout.dictionary(), layout.link_ids[i], layout.cells)
        _image(ax, bits, x + margin_mm, y + margin_mm, marker_mm, marker_mm)
        # The cut line sits just outside the plate, so the quiet zone survives the scissors.
        ax.add_patch(Rectangle((x - 0.5, y - 0.5), side + 1.0, side + 1.0, fill=False,
                               edgecolor=CUT_GREY, linewidth=0.4))
        name = "tail" if i == 0 else "head" if i == layout.n_links - 1 else "body"
        ax.text(x, y + side + 0.35 * GAP_MM,
                f"link {i + 1} ({name}), id {layout.link_ids[i]}   head \u2192",
                fontsize=7, va="center")
    return _save(fig, path)


def board_squares(spec: CharucoSpec) -> NDArray[np.uint8]:
    """The board's chessboard as one pixel per square (rows down the page): 0 black, 255 white."""
    sx, sy = spec.squares
    px = 20  # per square: enough to sample each square's colour clear of its marker
    img = np.asarray(spec.board().generateImage((sx * px, sy * px), marginSize=0, borderBits=1))
    probe = px // 10  # near the square's corner: inside the white margin around any marker
    return np.asarray(img[probe::px, probe::px][:sy, :sx], np.uint8)


def write_board_pdf(path: str | Path, spec: CharucoSpec) -> Path:
    """Write the ChArUco calibration board at true size on the smallest ISO A paper that holds it.

    The board's origin (its top-left outer corner on the page, docs/vision.md) is marked.

    Parameters
    ----------
    path : str or Path
        The ``.pdf`` to write.
    spec : CharucoSpec
        The board.

    Returns
    -------
    Path
        The file written.
    """
    sx, sy = spec.squares
    sq = spec.square_m * 1000.0
    w, h = sx * sq, sy * sq
    paper = iso_a_paper_mm((w, h))
    x0, y0 = (paper[0] - w) / 2, (paper[1] - h) / 2
    fig, ax = _page(paper)
    _image(ax, board_squares(spec), x0, y0, w, h)
    board = spec.board()
    dictionary = board.getDictionary()
    cells = int(dictionary.markerSize) + 2
    marker_mm = spec.marker_m * 1000.0
    ids = np.asarray(board.getIds()).ravel()
    for marker_id, corners in zip(ids, board.getObjPoints(), strict=True):
        tl = np.asarray(corners, dtype=float).reshape(4, 3)[0] * 1000.0  # metres on the page
        _image(ax, marker_bits(dictionary, int(marker_id), cells), x0 + tl[0], y0 + tl[1],
               marker_mm, marker_mm)
    ax.text(x0, y0 - 3.0, "origin: this corner (x along the rows, y up the page)", fontsize=7,
            va="bottom")
    ax.text(x0, y0 + h + 3.0,
            f"eelbot ChArUco board, {sx} x {sy} squares of {sq:g} mm, markers {marker_mm:g} mm, "
            f"{spec.dictionary_name} from id {spec.first_id}: print at 100 % (actual size)",
            fontsize=8, va="top")
    return _save(fig, path)
