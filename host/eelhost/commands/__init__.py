"""Subcommands of the eelbot command line, one module each."""
