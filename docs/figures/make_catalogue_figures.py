"""The screenshot of a catalogue's report in docs/pipeline.md.

Cuts the AHN3 Delft crop of ``../shared/data`` into tiles of 80 m, runs ``lidarstat
moments tiles/ out/ --dtm dtm/`` and photographs ``out/report/index.html`` in headless
Chromium::

    PYTHONPATH=src python docs/figures/make_catalogue_figures.py
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(ROOT / "benchmarks"))

from catalogue import DELFT  # noqa: E402

from lidarstat.io import read  # noqa: E402
from lidarstat.pipeline import write_tiles  # noqa: E402


def main():
    chromium = shutil.which("chromium")
    if chromium is None:
        raise SystemExit("chromium is needed (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        write_tiles(read(DELFT), tmp / "tiles", size=80.0)
        subprocess.run([sys.executable, "-m", "lidarstat", "moments", tmp / "tiles",
                        tmp / "out", "--dtm", tmp / "dtm", "-q"], check=True)
        shot = HERE / "catalogue_report_ahn3.png"
        subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu",
                        "--no-first-run", "--disable-background-networking",
                        "--disable-component-update", "--disable-sync",
                        f"--user-data-dir={tmp / 'profile'}", f"--screenshot={shot}",
                        "--window-size=1100,2200", "--hide-scrollbars",
                        (tmp / "out" / "report" / "index.html").as_uri()],
                       check=True, capture_output=True)
        print(shot)


if __name__ == "__main__":
    main()
