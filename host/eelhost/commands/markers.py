"""``eelbot markers``: the printable marker sheet and calibration board, and the marker file."""

from __future__ import annotations

import argparse

from eelhost.commands import COMMANDS
from eelhost.commands.common import OptionError, floats
from eelhost.commands.link_options import add_robot_file_option, resolve_robot_file_option
from eelhost.files import check_output_folder
from eelhost.vision.calibration import CalibrationError, CharucoSpec
from eelhost.vision.markerfile import MarkerFile, save_marker_file
from eelhost.vision.markers import MarkerLayout, MarkerLayoutError
from eelhost.vision.printing import write_board_pdf, write_marker_sheet_pdf
from eelsim.robot import load_robot


@COMMANDS.add(
    "markers",
    "write the printable marker sheet, the ChArUco board (PDF, true size) and markers.json",
)
def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register the subcommand."""
    p = sub.add_parser(
        "markers",
        help=COMMANDS.description("markers"),
        description="Write <out>/markers.pdf (one ArUco marker plate per link, A4), "
        "<out>/charuco.pdf (the calibration board on the smallest ISO A paper that holds it) and "
        "<out>/markers.json (what was printed: calibrate, run and campaign read it with "
        "--markers). Print both PDFs at 100 %% (actual size). Example: eelbot markers --out lab",
    )
    p.add_argument("--out", required=True, metavar="FOLDER", help="folder for the three files")
    add_robot_file_option(p, "robot TOML: one marker per link (default: the paper robot, 6 "
                          "links)")
    p.add_argument("--marker-size", type=float, default=0.060, help="black square, m (0.060)")
    p.add_argument("--margin", type=float, default=0.005, help="white quiet zone, m (0.005)")
    p.add_argument("--ids", metavar="I,J,...", help="marker id per link, tail first (0..N-1)")
    p.add_argument("--offsets", metavar="D,D,...", help="marker centre minus link centre along "
                   "the link, m, tail first (positive towards the head; default 0)")
    p.add_argument("--dictionary", default="DICT_4X4_50", help="ArUco dictionary (DICT_4X4_50)")
    p.add_argument("--board-squares", default="7,5", metavar="NX,NY", help="board squares (7,5)")
    p.add_argument("--board-square", type=float, default=0.11, help="board square, m (0.11)")
    p.add_argument("--board-marker", type=float, default=0.08, help="board marker, m (0.08)")
    p.add_argument("--board-first-id", type=int, default=10, help="board's first marker id (10)")
    p.set_defaults(run=run)


def _ints(text: str, what: str) -> tuple[int, ...]:
    values = floats(text, None, what)
    if any(v != int(v) for v in values):
        raise OptionError(f"{what}: expected whole numbers, got {text!r}")
    return tuple(int(v) for v in values)


def markers_from_args(args: argparse.Namespace) -> MarkerFile:
    """The marker file the options describe (errors name the option)."""
    resolve_robot_file_option(args)
    n_links = load_robot(args.robot_file).n_links
    try:
        ids = _ints(args.ids, "--ids") if args.ids else tuple(range(n_links))
        offsets = tuple(floats(args.offsets, n_links, "--offsets")) if args.offsets else ()
        squares = _ints(args.board_squares, "--board-squares")
    except argparse.ArgumentTypeError as err:
        raise OptionError(str(err)) from None
    if len(ids) != n_links:
        raise OptionError(f"--ids: the robot has {n_links} links, got {len(ids)} ids")
    if len(squares) != 2:
        raise OptionError(f"--board-squares: expected NX,NY, got {args.board_squares!r}")
    try:
        layout = MarkerLayout(args.dictionary, ids, args.marker_size, args.margin, offsets)
    except MarkerLayoutError as err:
        raise OptionError(f"--ids/--marker-size/--margin/--dictionary: {err}") from None
    try:
        board = CharucoSpec((squares[0], squares[1]), args.board_square, args.board_marker,
                            args.dictionary, args.board_first_id)
    except CalibrationError as err:
        raise OptionError(f"--board-*: {err}") from None
    return MarkerFile(layout, board)


def run(args: argparse.Namespace) -> int:
    """Run the subcommand."""
    markers = markers_from_args(args)
    out = check_output_folder(args.out)
    sheet = write_marker_sheet_pdf(out / "markers.pdf", markers.layout)
    board = write_board_pdf(out / "charuco.pdf", markers.board)
    layout_file = save_marker_file(markers, out / "markers.json")
    lay, b = markers.layout, markers.board
    print(f"{sheet}: {lay.n_links} plates, black square {lay.marker_size_m * 1000:g} mm "
          f"(plate {lay.plate_size_m * 1000:g} mm), ids {list(lay.link_ids)} tail first")
    print(f"{board}: {b.squares[0]} x {b.squares[1]} squares of {b.square_m * 1000:g} mm "
          f"({b.squares[0] * b.square_m * 1000:g} x {b.squares[1] * b.square_m * 1000:g} mm)")
    print(f"{layout_file}: the layout for --markers")
    print("print both at 100 % (actual size, no fit to page) and check a marker with a ruler")
    return 0
