"""The CLI registry: --help, subcommand discovery, one-line user errors."""
import importlib
import subprocess
import sys
import types

import pytest

from cdh_planner import __version__, cli
from cdh_planner.errors import InputError


def _fake_command(name, run):
    """A module like cdh_planner.commands.<name>, with add_parser/run."""
    mod = types.ModuleType(f'cdh_planner.commands.{name}')

    def add_parser(subparsers):
        p = subparsers.add_parser(name, help=f'fake {name} command')
        p.add_argument('--value', default='x')
        p.set_defaults(func=run)

    mod.add_parser = add_parser
    mod.run = run
    return mod


@pytest.fixture
def fake(monkeypatch):
    """Register fake subcommands under names of our own (not the real COMMANDS)."""
    def install(name, run):
        monkeypatch.setitem(sys.modules, f'cdh_planner.commands.{name}', _fake_command(name, run))
        monkeypatch.setattr(cli, 'COMMANDS', list(cli.COMMANDS) + [name])
    return install


def test_help_exits_0_and_lists_existing_commands(fake, capsys):
    fake('fakeok', lambda args: 0)
    assert cli.main(['--help']) == 0
    out = capsys.readouterr().out
    assert 'fakeok' in out
    for name in cli.COMMANDS:
        if cli._command_module(name) is not None:
            assert name in out


def test_a_new_command_is_one_file(tmp_path):
    """The command list and the summaries are read from the command modules' own headers
    (ORDER, SUMMARY; a module without SUMMARY is no command), without importing them: a
    module that would fail on import is listed all the same."""
    (tmp_path / 'hello.py').write_text(
        '"""``cdh-planner hello``."""\n\nORDER = 35  # its place\nSUMMARY = ("say "\n'
        '           "hello")\n\nimport no_such_module_xyz\n')
    (tmp_path / 'story').mkdir()
    (tmp_path / 'story' / '__init__.py').write_text('ORDER = 5\nSUMMARY = "tell it"\n')
    (tmp_path / 'helpers.py').write_text('"""Not a command."""\nORDER = 1\n')
    assert cli.declared_commands(tmp_path) == {'hello': (35, 'say hello'), 'story': (5, 'tell it')}
    # the package's own: every command module, in the order of --help
    assert cli.COMMANDS[:3] == ['verify', 'slice', 'plan'] and 'outputs' not in cli.COMMANDS
    assert set(cli.summaries()) == set(cli.COMMANDS)


def test_missing_command_modules_are_skipped(monkeypatch):
    monkeypatch.setattr(cli, 'COMMANDS', ['no_such_command_xyz'])
    parser = cli.build_parser()  # must not raise
    assert 'no_such_command_xyz' not in parser.format_help()


def test_version(capsys):
    assert cli.main(['--version']) == 0
    assert __version__ in capsys.readouterr().out


def test_no_command_is_usage_error(capsys):
    assert cli.main([]) == 2
    err = capsys.readouterr().err
    assert err == 'cdh-planner: error: the following arguments are required: COMMAND (see ' \
                  'cdh-planner --help)\n'


@pytest.mark.parametrize('argv, text', [
    (['plan', 'p.yaml', '--max-cable-speed', 'fast'], "invalid float value: 'fast'"),
    (['plan', 'p.yaml', '--strategy', 'best'], "invalid choice: 'best'"),
    (['plan'], 'required: problem'),
    (['plan', 'p.yaml', '--no-such-flag'], 'unrecognized arguments: --no-such-flag'),
    (['slice', 'r.yaml', '-o', 'x.png', '--resolution', '1.5'], "invalid int value: '1.5'"),
    (['call', '--goal', '0 0 0 0 0 0 1'], 'one of the arguments --start --current-start'),
    (['call', '--start', '1', '--current-start', '--goal', '1'], 'not allowed with'),
    (['no-such-command'], "invalid choice: 'no-such-command'"),
])
def test_usage_errors_are_one_line(capsys, argv, text):
    """argparse's errors without its usage text (13 lines for --max-cable-speed fast):
    exit 2, one line naming the argument, pointing at the command's --help."""
    assert cli.main(argv) == 2
    captured = capsys.readouterr()
    assert captured.out == ''
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith('cdh-planner: error: '), captured.err
    assert text in lines[0] and lines[0].endswith('--help)')


def test_usage_error_as_a_process_is_one_line():
    """Found by the bad-input campaign: ``plan P --max-cable-speed fast`` printed 13 lines."""
    proc = subprocess.run([sys.executable, '-m', 'cdh_planner.cli', 'plan', 'p.yaml',
                           '--max-cable-speed', 'fast'], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 2 and proc.stdout == ''
    assert proc.stderr == "cdh-planner: error: argument --max-cable-speed: invalid float " \
                          "value: 'fast' (see cdh-planner plan --help)\n"


def test_handler_return_code_is_passed_through(fake):
    fake('fakerc', lambda args: 7)
    assert cli.main(['fakerc']) == 7


def test_input_error_is_one_line_exit_2(fake, capsys):
    def run(args):
        raise InputError('limits.length_min[2]', -1.0, 'must be positive')

    fake('fakebad', run)
    assert cli.main(['fakebad']) == 2
    captured = capsys.readouterr()
    err = captured.err
    assert err == "cdh-planner: error: limits.length_min[2] = -1.0: must be positive\n"
    assert 'Traceback' not in err + captured.out


def test_file_not_found_names_the_path(fake, capsys):
    def run(args):
        open('/nonexistent/robot.yaml')

    fake('fakefnf', run)
    assert cli.main(['fakefnf']) == 2
    err = capsys.readouterr().err
    assert err.startswith('cdh-planner: error:')
    assert '/nonexistent/robot.yaml' in err
    assert 'Traceback' not in err
    assert len(err.strip().splitlines()) == 1


def test_keyboard_interrupt_is_130(fake):
    def run(args):
        raise KeyboardInterrupt

    fake('fakeint', run)
    assert cli.main(['fakeint']) == 130


def test_console_script_help_runs():
    """The module runs as a process (same code path as the cdh-planner script)."""
    proc = subprocess.run([sys.executable, '-m', 'cdh_planner.cli', '--help'],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert 'usage: cdh-planner' in proc.stdout


def _raise_name_error():
    from rclpy.exceptions import InvalidTopicNameException
    raise InvalidTopicNameException('/bad topic!!', 'must not contain spaces', 4)


def _raise_crc_error():
    from mcap.exceptions import RecordLengthLimitExceeded
    raise RecordLengthLimitExceeded(6, 1 << 40, 1000)


@pytest.mark.parametrize('raise_it, module', [(_raise_name_error, 'rclpy'),
                                              (_raise_crc_error, 'mcap')])
def test_library_exceptions_of_bad_input_are_exit_2(fake, capsys, raise_it, module):
    """rclpy's name errors and mcap's read errors that escape a command are bad input
    (cli.INPUT_EXCEPTIONS, by qualified name, subclasses included), not internal errors."""
    pytest.importorskip(module)
    fake('fakelib', lambda args: raise_it())
    assert cli.main(['fakelib']) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith('cdh-planner: error: ')
    assert 'internal error' not in lines[0]


def test_other_library_exceptions_stay_internal(fake, capsys):
    class McapError(Exception):   # same name, another module: not the library's
        pass

    fake('fakeother', lambda args: (_ for _ in ()).throw(McapError('x')))
    assert cli.main(['fakeother']) == 3
    assert 'internal error: McapError: x' in capsys.readouterr().err


def test_input_exception_names_are_the_libraries_own():
    """cli.INPUT_EXCEPTIONS names classes that exist under those names (a rename in rclpy
    or mcap would silently make them exit 3 again)."""
    for qualified in cli.INPUT_EXCEPTIONS:
        module, _, name = qualified.rpartition('.')
        pytest.importorskip(module.split('.')[0])
        cls = getattr(importlib.import_module(module), name)
        assert issubclass(cls, Exception) and cls.__module__ == module, qualified


_TEARDOWN_PROBE = """import atexit, json, sys
from cdh_planner import cli
atexit.register(lambda: print('TEARDOWN'))
sys.argv = ['cdh-planner', *json.loads(sys.argv[1])]
sys.exit(cli.main())
"""


@pytest.mark.parametrize('quick', [True, False])
def test_a_quick_exit_command_ends_without_teardown_and_loses_no_output(tmp_path, quick):
    """``verify`` declares QUICK_EXIT: its process ends once its outputs are closed and
    stdout is written (every report line, the JSON whole, its exit code), without the
    interpreter's teardown (an atexit handler does not run); ``urdf`` does not declare it."""
    from pathlib import Path
    import json
    repo = Path(__file__).resolve().parents[1]
    poses = tmp_path / 'poses.json'
    poses.write_text(json.dumps([{'position': [0.0, 0.0, 0.3 + 1e-4 * k], 'tau': [0.0, 0.1, 0.0]}
                                 for k in range(300)]))
    out = tmp_path / ('out.json' if quick else 'out.urdf')
    argv = (['verify', str(repo / 'config/robot2.yaml'), str(poses), '--all', '--json', str(out)]
            if quick else ['urdf', str(repo / 'config/robot2.yaml'), '-o', str(out)])
    proc = subprocess.run([sys.executable, '-c', _TEARDOWN_PROBE, json.dumps(argv)],
                          capture_output=True, text=True, timeout=120, cwd=repo)
    assert proc.returncode == 0 and proc.stderr == '', proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[-1] == ('TEARDOWN' if not quick else f'wrote {out}')
    if quick:
        assert sum(line.startswith('pose ') for line in lines) == 300
        assert len(json.loads(out.read_text())['poses']) == 300
