"""Running usdfacedyn in-process the way a shell would: exit code, stdout, stderr."""
from facedyn.cli import main


def run(argv, capsys):
    """(exit code, stdout, stderr) of `usdfacedyn ARGV`; argparse's exits count as exit codes."""
    try:
        code = main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err
