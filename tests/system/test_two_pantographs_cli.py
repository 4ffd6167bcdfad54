"""A case with a [second_pantograph] on the command line: the commands that run one pantograph refuse it in
one line and write nothing (a result without the second is not the case's); `pantohil direct` gives the pair's
closed form at the section's spacing."""
import pytest

from conftest import pantohil

PAIR = ("--set", "second_pantograph.spacing_m=200")


@pytest.mark.parametrize("command", [("run",), ("stability",)])
def test_a_command_for_one_pantograph_refuses_a_case_with_two(command, tmp_path):
    out = tmp_path / "out"
    done = pantohil(*command, *PAIR, "--out", str(out))
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and "second_pantograph: " in lines[0] and "runs one pantograph" in lines[0]
    assert not out.exists()


def test_direct_takes_the_spacing_of_the_case(tmp_path):
    done = pantohil("direct", *PAIR)
    assert done.returncode == 0, done.stderr
    assert "two pantographs 200 m apart: leading std 18.915 N, trailing std 20.051 N" in done.stdout
