"""The ``eelbot`` command line."""

import argparse


def main(argv: list[str] | None = None) -> int:
    """Run the eelbot command line."""
    parser = argparse.ArgumentParser(prog="eelbot")
    parser.parse_args(argv)
    return 0
