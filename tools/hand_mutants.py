"""Apply each one-line bug of issue 14 in turn, run the answer-key tests, report the killers.

Each bug is a (file, old text, new text) replacement; the file is restored afterwards, so
run nothing else in this working copy meanwhile. The tests run with tools/mutmut_plugin.py
(no hypothesis shrinking). From the repository root:

    python tools/hand_mutants.py [pytest args, default tests/core/test_answer_keys.py]
"""

import os
import subprocess
import sys
from pathlib import Path

BUGS = {
    "basis centres off by one": (
        "dmpopt/basis.py",
        "np.linspace(0.0, end, n_basis)",
        "np.linspace(0.0, end, n_basis + 1)[1:]",
    ),
    "LWR weighted by psi^2": (
        "dmpopt/fitting/imitation.py",
        'np.einsum("ti,tab->iab", activation, outer)',
        'np.einsum("ti,tab->iab", activation**2, outer)',
    ),
    "LWR weighted by psi^2 (cross term too)": (
        "dmpopt/fitting/imitation.py",
        'cross = np.einsum("ti,tad->iad", activation,',
        'cross = np.einsum("ti,tad->iad", activation**2,',
    ),
    "energy phase reset, sin and cos swapped": (
        "dmpopt/stepper.py",
        "self._state[0] = amplitude * np.cos(phase)\n"
        "            self._state[1] = amplitude * self.dmp.k * np.sin(phase)",
        "self._state[0] = amplitude * np.sin(phase)\n"
        "            self._state[1] = amplitude * self.dmp.k * np.cos(phase)",
    ),
    "set_goal does not refresh the forcing weights": (
        "dmpopt/stepper.py",
        "self._function.set_inputs(forcing_weights=weights)",
        "pass",
    ),
    "forcing sign flipped (velocity form)": (
        "dmpopt/symbolic.py",
        "return ca.vertcat(z + forcing,",
        "return ca.vertcat(z - forcing,",
    ),
    "forcing sign flipped (acceleration form)": (
        "dmpopt/symbolic.py",
        "alpha_z * (beta_z * (r - y) - z) + forcing + coupling",
        "alpha_z * (beta_z * (r - y) - z) - forcing + coupling",
    ),
    "stepper velocity and acceleration swapped": (
        "dmpopt/stepper.py",
        "            velocity.copy(),\n            acceleration.copy(),",
        "            acceleration.copy(),\n            velocity.copy(),",
    ),
}


def main(pytest_args):
    for name, (path, old, new) in BUGS.items():
        source = Path(path)
        original = source.read_text()
        if original.count(old) != 1:
            print(f"{name}: pattern not found once in {path}; update this script")
            continue
        source.write_text(original.replace(old, new))
        try:
            result = subprocess.run(
                [
                    sys.executable,
                    "-m",
                    "pytest",
                    "-q",
                    "-rf",
                    "-p",
                    "no:cacheprovider",
                    "-p",
                    "mutmut_plugin",
                    *pytest_args,
                ],
                capture_output=True,
                text=True,
                env={**os.environ, "PYTHONPATH": str(Path(__file__).parent)},
            )
        finally:
            source.write_text(original)
        killers = [
            line.split()[1] for line in result.stdout.splitlines() if line.startswith("FAILED")
        ]
        print(f"{name}: {'KILLED' if killers else 'SURVIVED'} by {len(killers)} test(s)")
        for killer in killers:
            print(f"    {killer}")


if __name__ == "__main__":
    main(sys.argv[1:] or ["tests/core/test_answer_keys.py"])
