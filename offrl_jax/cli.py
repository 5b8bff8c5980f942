"""The argument parser every command of the project uses: bad input is one line, `error: ...`, exit 2."""
from __future__ import annotations

import argparse
import sys


class OneLineParser(argparse.ArgumentParser):
    """argparse with a one-line error (argparse prints usage + error) and no prefix matching of flags ("--pretrain"
    must not silently mean "--pretrain-updates")."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **{"allow_abbrev": False} | kwargs)

    def error(self, message: str):
        print(f"error: {message}", file=sys.stderr)
        sys.exit(2)
