"""argparse value types shared by the command-line tools (`ehm_drake.cli`
and the gap diagnosis' commands in `ehm_drake.gap.commands`)."""

from __future__ import annotations

import argparse


def int_at_least(lo: int):
    """An argparse type: an integer >= `lo`, with a message naming the value."""

    def parse(text):
        try:
            v = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if v < lo:
            raise argparse.ArgumentTypeError(f"must be >= {lo}, got {v}")
        return v

    return parse
