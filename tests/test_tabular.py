import json
import subprocess
import sys

from experiments.tabular import table1

# Table 1 of the paper, epochs 0..3, columns Q(0,->), Q(1,<-), Q(1,->), Q(2,->)
ZERO = [[0, 0, 0, 0], [0, -1, -2, 3], [-2, -2, 1, 3], [1, 0, 1, 3]]
MC = [[0.5, 0, 1, 3], [1, 0, 1, 3], [1, 0, 1, 3], [1, 0, 1, 3]]  # every-visit MC: Q(0,->) = (0 + 1) / 2


def test_table1_exact():
    assert table1() == {"zero": ZERO, "mc": MC}


def test_cli_json():
    out = subprocess.run([sys.executable, "-m", "experiments.tabular", "--json"], capture_output=True, text=True,
                         check=True).stdout
    assert json.loads(out) == {"zero": ZERO, "mc": MC}
