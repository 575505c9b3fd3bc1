# Copyright 2026 epp_ros developers
#
# Licensed under the Apache License, Version 2.0 (the "License");
# you may not use this file except in compliance with the License.
# You may obtain a copy of the License at
#
#     http://www.apache.org/licenses/LICENSE-2.0
#
# Unless required by applicable law or agreed to in writing, software
# distributed under the License is distributed on an "AS IS" BASIS,
# WITHOUT WARRANTIES OR CONDITIONS OF ANY KIND, either express or implied.
# See the License for the specific language governing permissions and
# limitations under the License.

"""
epp_demo's live view: the drawing as a plain function, and the demo under a pseudo-terminal.

The pseudo-terminal tests wait for conditions on the screen with generous timeouts (the
machine may be slow and busy), never for a fixed time.
"""
import fcntl
import os
from pathlib import Path
import pty
import re
import select
import signal
import struct
import subprocess
import sys
import termios
import time

from epp_ros.app import bags
from epp_ros.app.health import nlos_pairs, nlos_text
from epp_ros.cli import demo
from epp_ros.cli.demo_view import Canvas, draw, GLYPHS, side_view, STYLES, to_rich, top_view
import numpy as np
import pytest

TIMEOUT = 240.0         # s: for anything to happen on a busy 2-core machine
COLUMNS, LINES = 90, 28
ANSI = re.compile(r'\x1b\[[0-9;?]*[A-Za-z]|\x1b[()][0-9A-Za-z]|\r')
LEAVE_ALT_SCREEN, SHOW_CURSOR, HOME = '\x1b[?1049l', '\x1b[?25h', '\x1b[H'

# A horizontal boom 2 m up, pointing along +x: the pivot on the slew axis, joints at 10
# and 20 m.
HORIZONTAL = np.array([[0.0, 0.0, 2.0], [10.0, 0.0, 2.0], [20.0, 0.0, 2.0]])


def test_canvas_maps_the_world_to_cells_twice_as_tall_as_wide():
    canvas = Canvas(10, 5, (0.0, 10.0), (0.0, 10.0))
    assert (canvas.dx, canvas.dy) == (1.0, 2.0)
    assert canvas.cell(0.5, 9.5) == (0, 0)
    assert canvas.cell(2.5, 9.0) == (0, 2)
    assert canvas.cell(9.9, 0.1) == (4, 9)
    assert canvas.cell(10.5, 5.0) is None and canvas.cell(float('nan'), 1.0) is None
    canvas.line((0.0, 5.0), (10.0, 5.0))
    assert canvas.drawing().rows[2] == '-' * 10
    canvas.line((4.5, 0.0), (4.5, 10.0))
    assert all(row[4] == '|' for row in canvas.drawing().rows)


def test_side_view_puts_the_tip_at_its_cell_and_the_ground_below():
    drawing = side_view(HORIZONTAL, width=50, height=10, axis=(0.0, 0.0), span=20.0,
                        top=10.0)
    # The view spans reach -4 .. 21 m and height -0.8 .. 10.5 m, widened to square metres:
    # 0.565 m a column, 1.13 m a row, from reach -5.625 m and height 10.5 m. The tip
    # (reach 20 m, 2 m up) is in column (20 + 5.625) / 0.565 = 45.4, row 8.5 / 1.13 = 7.5.
    assert drawing.find(GLYPHS['tip']) == [(7, 45)]
    assert drawing.find(GLYPHS['pivot']) == [(7, 9)]
    assert drawing.find('1') == [(7, 27)]                 # 10 m: column 27.6
    assert set(drawing.rows[7][10:27]) == {'-'}           # the section between them
    ground = drawing.rows[9]                              # height 0: row 9.3
    assert set(ground) == {GLYPHS['ground'], GLYPHS['mast']}
    assert ground[9] == GLYPHS['mast']                    # the slew axis under the pivot
    assert drawing.rows[0].startswith('side')
    assert len(drawing.rows) == 10 and {len(row) for row in drawing.rows} == {50}


def test_side_view_shows_the_reach_in_the_boom_plane_whatever_the_slew():
    slewed = HORIZONTAL.copy()
    slewed[:, :2] = slewed[:, :2] @ np.array([[0.0, 1.0], [-1.0, 0.0]])     # along +y
    assert side_view(slewed, width=50, height=10, axis=(0.0, 0.0), span=20.0,
                     top=10.0).rows == side_view(HORIZONTAL, width=50, height=10,
                                                 axis=(0.0, 0.0), span=20.0, top=10.0).rows


def test_uncertainty_is_drawn_around_its_joint_and_only_there():
    kwargs = {'width': 50, 'height': 10, 'axis': (0.0, 0.0), 'span': 20.0, 'top': 10.0}
    assert not side_view(HORIZONTAL, stds=[0.0, 0.0], **kwargs).find(GLYPHS['uncertainty'])
    assert not side_view(HORIZONTAL, stds=[np.nan, np.nan],
                         **kwargs).find(GLYPHS['uncertainty'])
    # 0.3 m drawn 10x: a disc of 3 m around the tip, 5 columns and 2 rows either side
    # (on the left the section is drawn over it).
    drawing = side_view(HORIZONTAL, stds=[0.0, 0.3], **kwargs)
    cells = drawing.find(GLYPHS['uncertainty'])
    assert cells and drawing.find(GLYPHS['tip']) == [(7, 45)]
    assert all(abs(r - 7) <= 3 and abs(c - 45) <= 6 for r, c in cells)
    assert {(6, 45), (8, 45), (7, 46), (7, 49), (5, 45), (9, 45)} <= set(cells)
    plan = top_view(HORIZONTAL, stds=[0.0, 0.3], width=40, height=20, axis=(0.0, 0.0),
                    span=20.0)
    (tip_row, tip_column), = plan.find(GLYPHS['tip'])
    assert (tip_row - 1, tip_column) in plan.find(GLYPHS['uncertainty'])        # 2.1 m up


def test_the_truth_is_drawn_under_the_estimate():
    truth = HORIZONTAL + [0.0, 0.0, 5.0]        # 5 m above: clear of the estimate
    drawing = side_view(HORIZONTAL, truth, width=50, height=10, axis=(0.0, 0.0), span=20.0,
                        top=10.0)
    assert len(drawing.find(GLYPHS['truth_joint'])) == 2
    assert drawing.find(GLYPHS['truth_line'])
    covered = side_view(HORIZONTAL, HORIZONTAL, width=50, height=10, axis=(0.0, 0.0),
                        span=20.0, top=10.0)
    assert not covered.find(GLYPHS['truth_joint'])


def test_top_view_shows_the_slew():
    north = HORIZONTAL.copy()
    north[:, :2] = north[:, :2] @ np.array([[0.0, 1.0], [-1.0, 0.0]])      # along +y
    plan = top_view(north, width=40, height=20, axis=(0.0, 0.0), span=20.0)
    (tip_row, tip_column), = plan.find(GLYPHS['tip'])
    (pivot_row, pivot_column), = plan.find(GLYPHS['pivot'])
    assert tip_column == pivot_column and tip_row < pivot_row - 5
    east = top_view(HORIZONTAL, width=40, height=20, axis=(0.0, 0.0), span=20.0)
    (tip_row, tip_column), = east.find(GLYPHS['tip'])
    (pivot_row, pivot_column), = east.find(GLYPHS['pivot'])
    assert tip_row == pivot_row and tip_column > pivot_column + 10


def test_draw_fills_the_canvas_with_both_views_and_converts_to_rich():
    drawing = draw(HORIZONTAL, HORIZONTAL + 0.5, [0.1, 0.2], width=90, height=20)
    assert len(drawing.rows) == 20 and {len(row) for row in drawing.rows} == {90}
    assert len(drawing.styles) == 20 and {len(row) for row in drawing.styles} == {90}
    assert 'side' in drawing.rows[0] and 'top' in drawing.rows[0]
    assert len(drawing.find(GLYPHS['tip'])) == 2           # one in each view
    assert to_rich(drawing).plain == drawing.text
    moved = draw(HORIZONTAL + [0.0, 0.0, 4.0], None, None, width=90, height=20)
    assert moved.rows != draw(HORIZONTAL, None, None, width=90, height=20).rows
    with pytest.raises(ValueError):
        draw(np.zeros((3, 2)), width=90, height=20)


# Anchor 1 15 m south of joint 1 (10 m east), anchor 2 north-west of the pivot.
ANCHORS = np.array([[10.0, -15.0, 0.5], [-5.0, 5.0, 0.5]])


def test_a_flagged_link_is_marked_from_its_joint_to_its_anchor():
    kwargs = {'width': 40, 'height': 20, 'axis': (0.0, 0.0), 'span': 20.0,
              'anchors': ANCHORS}
    # 1.05 m a column, 2.1 m a row from (-21, 21) m: joint 1 (10, 0) is in row 10, column
    # 29; anchor 1 (10, -15) in row 17, same column; anchor 2 (-5, 5) in row 7, column 15.
    clear = top_view(HORIZONTAL, **kwargs)
    assert clear.find(GLYPHS['anchor']) == [(7, 15), (17, 29)]
    assert not clear.find(GLYPHS['nlos'])
    assert STYLES['nlos'] not in (clear.styles[10][29], clear.styles[17][29])
    flagged = top_view(HORIZONTAL, nlos=[(1, 1)], **kwargs)
    assert flagged.find(GLYPHS['nlos']) == [(row, 29) for row in range(11, 17)]
    assert flagged.rows[10][29] == '1' and flagged.rows[17][29] == GLYPHS['anchor']
    assert flagged.styles[10][29] == flagged.styles[17][29] == STYLES['nlos']
    assert flagged.styles[7][15] == STYLES['anchor']                # anchor 2: not flagged
    # Under the boom: from joint 2 to an anchor under the pivot the link runs along the
    # sections, which are drawn over it.
    turret = dict(kwargs, anchors=[[0.0, 0.0, 3.5]])
    along = top_view(HORIZONTAL, nlos=[(2, 1)], **turret)
    assert along.rows == top_view(HORIZONTAL, **turret).rows
    assert not along.find(GLYPHS['nlos']) and along.styles[10][39] == STYLES['nlos']
    # Links naming no drawn joint or anchor are left out; without anchors only the joint.
    assert top_view(HORIZONTAL, nlos=[(3, 1), (1, 3)], **kwargs).rows == clear.rows
    bare = top_view(HORIZONTAL, nlos=[(1, 1)], **dict(kwargs, anchors=None))
    assert not bare.find(GLYPHS['anchor']) and not bare.find(GLYPHS['nlos'])
    assert bare.styles[10][29] == STYLES['nlos']
    # Both views colour the joint; only the top view draws the link.
    both = draw(HORIZONTAL, None, None, width=90, height=20, anchors=ANCHORS, nlos=[(1, 1)])
    side_width = 90 - 40 - 2
    joints = [(r, c) for r, c in both.find('1') if c < side_width]
    assert joints and all(both.styles[r][c] == STYLES['nlos'] for r, c in joints)
    assert all(c > side_width for _, c in both.find(GLYPHS['nlos']))


def test_the_demo_reads_and_lists_the_flagged_links():
    blocked = np.zeros((5, 6), dtype=bool)
    blocked[1, 2] = blocked[4, 0] = True
    text = nlos_text(blocked)
    assert text == '2:3 5:1' and nlos_pairs(text) == [(2, 3), (5, 1)]
    assert nlos_pairs('') == nlos_pairs(None) == nlos_pairs('a:1 2') == []
    assert demo.nlos_line({'NLOS links': '2', 'NLOS flagged links': text}) == \
        'NLOS links 2: joint 2-anchor 3, joint 5-anchor 1'
    assert demo.nlos_line({'NLOS links': '3', 'NLOS flagged links': '1:2 1:5 3:4'}) == \
        'NLOS links 3: joint 1-anchors 2 5, joint 3-anchor 4'
    assert demo.nlos_line({'NLOS links': '3', 'NLOS flagged links': '1:2 1:5 3:4'}, 40) == \
        'NLOS links 3 (joint-anchor): 1-2 1-5 3-4'
    assert demo.nlos_line({'NLOS links': '0', 'NLOS flagged links': ''}) == 'NLOS links 0'
    assert demo.nlos_line({}) == 'NLOS links -'


def test_the_live_view_marks_the_flagged_links():
    from io import StringIO
    from rich.console import Console
    monitor = object.__new__(demo.Monitor)          # its numbers, without a ROS node
    monitor.__dict__.update(
        latencies=[0.01], rmses=[0.1], max_error=0.2, posture_stamps=[(1, 0)],
        frame_stamps=[(1, 0)], posture_times=[], last=(HORIZONTAL, HORIZONTAL),
        estimate=HORIZONTAL, level='WARN', reason='1 of 12 links look blocked',
        values={'NLOS links': '1', 'NLOS flagged links': '1:1'})
    scene = {'axis': (0.0, 0.0), 'span': 20.0, 'top': 10.0, 'anchors': ANCHORS}
    console = Console(file=StringIO(), width=COLUMNS, color_system=None)
    console.print(demo.live_view(monitor, demo.parse_args(['--method', 'chain']), 1.0,
                                 COLUMNS, LINES, scene))
    screen = console.file.getvalue()
    assert 'NLOS links 1: joint 1-anchor 1' in screen and ' x NLOS link' in screen
    rows = _drawing(screen)
    assert any(GLYPHS['anchor'] in row for row in rows)
    assert any(GLYPHS['nlos'] in row for row in rows)


def test_field_and_noise_options():
    args = demo.parse_args(['--field', 'nlos_persistent,tdma'])
    assert args.field == 'nlos_persistent,tdma' and args.sigma is None
    assert demo.emulator_noise(args) == ['--field', 'nlos_persistent,tdma']
    args = demo.parse_args([])
    assert (args.sigma, args.drop, args.nlos, args.plain) == (0.1, 0.05, 0.0, False)
    assert demo.emulator_noise(args)[:2] == ['--sigma', '0.1']
    with pytest.raises(SystemExit):
        demo.parse_args(['--field', 'nlos_persistent', '--sigma', '0.2'])
    with pytest.raises(SystemExit):
        demo.parse_args(['--field', 'rain'])


def test_a_calibrated_description_goes_to_driver_and_estimator(tmp_path, capsys):
    args = demo.parse_args(['--calibrated', str(tmp_path / 'calibrated.yaml'),
                            '--field', 'offsets'])
    emulator, driver, estimator = demo.pipeline_commands(args, 'pump.yaml', 'LINK')
    assert emulator[emulator.index('--config') + 1] == 'pump.yaml'
    assert 'offsets' in emulator
    for node in (driver, estimator):
        assert node[node.index('--params-file') + 1] == str(tmp_path / 'calibrated.yaml')
    args = demo.parse_args([])
    assert all(command[command.index('--params-file') + 1] == 'pump.yaml'
               for command in demo.pipeline_commands(args, 'pump.yaml', 'LINK')[1:])
    # A description that cannot be read stops the demo with one line.
    assert demo.main(['--calibrated', str(tmp_path / 'missing.yaml'), '--duration', '1']) == 2
    assert capsys.readouterr().err.count('\n') == 1


def test_record_refuses_an_existing_bag(tmp_path, capsys):
    with pytest.raises(SystemExit) as stopped:      # argparse's one line, before it runs
        demo.main(['--record', str(tmp_path), '--duration', '1'])
    assert stopped.value.code == 2 and 'exists already' in capsys.readouterr().err


PLAIN_LINE = re.compile(r'postures \d+   \d+\.\d Hz   running RMSE (\d+\.\d+|nan) m   '
                        r'latency p50 (\d+\.\d+|nan) ms  p99 (\d+\.\d+|nan) ms   '
                        r'diagnostics (OK|WARN|ERROR|STALE|-)   unanswered frames \d+')


def test_plain_lines_field_effects_and_a_recording(tmp_path):
    bag = tmp_path / 'shown'
    result = subprocess.run(
        [sys.executable, '-m', 'epp_ros.cli.demo', '--plain', '--postures', '60',
         '--duration', str(TIMEOUT / 2), '--field', 'nlos_persistent', '--garbage', '0',
         '--record', str(bag)],
        capture_output=True, text=True, timeout=TIMEOUT)
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    summary = [line for line in lines if line.startswith('epp_demo: ')]
    shown = [line for line in lines if line.startswith('postures ')]
    assert len(summary) == 1 and len(shown) >= 3 and '\x1b' not in result.stdout
    assert all(PLAIN_LINE.fullmatch(line) for line in shown), shown
    assert any(line.startswith('recorded ') for line in lines)
    counts = {topic: count for topic, (_, count) in _topics(bag).items()}
    assert counts.get(bags.POSTURE, 0) >= 20 and counts.get(bags.TRUTH, 0) >= 20
    assert counts.get(bags.RANGES, 0) >= 20 and counts.get('/diagnostics', 0) >= 1


def _topics(bag):
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        return {c.topic: (c.msgtype, c.msgcount) for c in reader.connections}


class Terminal:
    """A program on a pseudo-terminal of its own (its controlling terminal): Ctrl-C works."""

    def __init__(self, argv):
        env = dict(os.environ, COLUMNS=str(COLUMNS), LINES=str(LINES), TERM='xterm-256color')
        env.pop('NO_COLOR', None)
        self.pid, self.fd = pty.fork()
        if self.pid == 0:                               # the child: becomes the program
            try:
                os.execve(argv[0], argv, env)
            finally:
                os._exit(127)
        fcntl.ioctl(self.fd, termios.TIOCSWINSZ, struct.pack('HHHH', LINES, COLUMNS, 0, 0))
        self.output = ''
        self._pending = b''
        self.status = None

    def read(self, timeout=0.2):
        """Append what the program wrote within ``timeout`` s; False once it closed."""
        ready, _, _ = select.select([self.fd], [], [], timeout)
        if not ready:
            return True
        try:
            data = os.read(self.fd, 65536)
        except OSError:                                 # EIO: the program's side closed
            return False
        if not data:
            return False
        self._pending += data
        text = self._pending.decode('utf-8', errors='ignore')
        if text.encode('utf-8') == self._pending:       # no character cut in half
            self.output += text
            self._pending = b''
        return True

    def screens(self):
        """Return the screens drawn so far: each redraw starts at the home position."""
        return [ANSI.sub('', screen) for screen in self.output.split(HOME)[1:]]

    def wait_for(self, condition, timeout=TIMEOUT):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if condition():
                return True
            if not self.read():
                return condition()
        return False

    def wait_exit(self, timeout=TIMEOUT):
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and self.status is None:
            self.read()
            pid, status = os.waitpid(self.pid, os.WNOHANG)
            if pid:
                self.status = os.waitstatus_to_exitcode(status)
        while self.read(0.05):                          # what is left in the pty
            pass
        return self.status

    def close(self):
        if self.status is None:
            try:
                os.killpg(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            os.waitpid(self.pid, 0)
        os.close(self.fd)


def _drawing(screen):
    """Return the rows of a screen between its header and the legend."""
    rows = screen.split('\n')
    legend = next((i for i, row in enumerate(rows) if row.startswith('estimate ')), len(rows))
    return rows[1:legend]


def _complete(screen):
    return (GLYPHS['tip'] in screen and GLYPHS['pivot'] in screen and 'side' in screen
            and re.search(r'health (OK|WARN|ERROR|STALE)', screen) is not None
            and 'method chain' in screen and re.search(r'RMSE \d+\.\d+ m', screen) is not None)


def test_the_live_view_under_a_pseudo_terminal_and_ctrl_c():
    script = Path(sys.executable).parent / 'epp_demo'
    argv = ([str(script)] if script.exists()
            else [sys.executable, '-m', 'epp_ros.cli.demo'])
    terminal = Terminal(argv + ['--method', 'chain', '--duration', '600'])
    try:
        assert terminal.wait_for(lambda: any(map(_complete, terminal.screens()))), \
            terminal.output[-3000:]
        first = next(s for s in terminal.screens() if _complete(s))
        rows = _drawing(first)
        assert any(row.count(GLYPHS['ground']) > 20 for row in rows)       # the ground
        assert 'learned noise' in first and 'unanswered frames' in first
        assert re.search(r'latency p50 \d+\.\d ms', first)
        # The boom moves: a later screen draws it elsewhere.
        assert terminal.wait_for(lambda: any(
            _complete(s) and _drawing(s) != rows for s in terminal.screens()[-3:])), \
            terminal.screens()[-1]
        shown = len(terminal.output)
        os.write(terminal.fd, b'\x03')                  # Ctrl-C, as a user types it
        assert terminal.wait_exit() == 0, terminal.output[-3000:]
        after = terminal.output[shown:]
        # The terminal is given back: the alternate screen left, the cursor shown, after
        # the last redraw; then the summary on the normal screen.
        assert LEAVE_ALT_SCREEN in after and SHOW_CURSOR in after
        assert terminal.output.rfind(HOME) < terminal.output.rfind(LEAVE_ALT_SCREEN)
        summary = ANSI.sub('', after[after.rfind(LEAVE_ALT_SCREEN):])
        assert re.search(r'epp_demo: \d+ postures, RMSE \d+\.\d+ m', summary), summary
        assert 'Traceback' not in terminal.output
    finally:
        terminal.close()
    # The captured screen, without escape codes, for the README.
    print('\n'.join(row.rstrip() for row in first.split('\n')))
