"""`python -m gtsam_dvl.app.live --write-layout`: regenerate layout.json (package data) from layout()."""

from __future__ import annotations

import sys

from gtsam_dvl.app.live.layout import write_layout

if __name__ == "__main__":  # pragma: no cover
    if sys.argv[1:] == ["--write-layout"]:
        print(write_layout())
    else:
        sys.exit("usage: python -m gtsam_dvl.app.live --write-layout")
