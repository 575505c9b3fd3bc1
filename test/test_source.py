"""The transport against a real pseudo-terminal and a real TCP socket."""
import os
import socket
import threading
import time
import tty

import pytest

from epp_ros.uwb.source import LineSource, LineSplitter


def wait_for(condition, timeout=5.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.01)
    return False


def test_splitter_joins_partial_lines_and_strips_line_ends():
    splitter = LineSplitter()
    assert splitter.feed(b'mc 07 0000') == []
    assert splitter.feed(b'04ec\r\nsecond li') == ['mc 07 000004ec']
    assert splitter.feed(b'ne\n\n\r\n') == ['second line']


def test_splitter_replaces_bad_bytes_and_bounds_lines():
    splitter = LineSplitter(max_line=16)
    assert splitter.feed(b'\xff\xfeok\n') == ['\ufffd\ufffdok']
    assert splitter.feed(b'x' * 40) == []
    assert splitter.feed(b'y' * 40 + b'\nnext\n') == ['next']
    assert splitter.overlong == 1
    assert splitter.feed(b'z' * 17 + b'\n') == [] and splitter.overlong == 2


def collect():
    lines = []
    return lines, lambda line, stamp: lines.append((line, stamp))


def test_reads_a_pseudo_terminal_and_reconnects_after_unplugging(tmp_path):
    link = tmp_path / 'ttyUWB'
    master, slave = os.openpty()
    tty.setraw(slave)
    os.symlink(os.ttyname(slave), link)
    lines, on_line = collect()
    source = LineSource(str(link), on_line, backoff=0.2).start()
    try:
        assert wait_for(lambda: source.state == 'connected')
        os.write(master, b'\x00\x9cnoise\r\nfrom: 1782\t Range: 2.34 m\r\n')
        assert wait_for(lambda: any('Range' in line for line, _ in lines))
        assert lines[-1][0] == 'from: 1782\t Range: 2.34 m'
        # Unplug: the device disappears.
        os.close(master)
        os.close(slave)
        link.unlink()
        assert wait_for(lambda: source.state == 'disconnected')
        errors = source.counts['io_errors']
        assert wait_for(lambda: source.counts['io_errors'] > errors + 1)   # keeps trying
        # Plug a new device in under the same name.
        master, slave = os.openpty()
        tty.setraw(slave)
        os.symlink(os.ttyname(slave), link)
        assert wait_for(lambda: source.state == 'connected')
        time.sleep(0.1)
        os.write(master, b'after replug\n')
        assert wait_for(lambda: lines[-1][0] == 'after replug')
        assert source.counts['reconnects'] == 1
    finally:
        source.stop()
        for fd in (master, slave):
            try:
                os.close(fd)
            except OSError:
                pass


class Bridge:
    """A minimal TCP server that sends what it is given to its one client."""

    def __init__(self, port=0):
        self.server = socket.create_server(('127.0.0.1', port))
        self.port = self.server.getsockname()[1]
        self.client = None
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        try:
            self.client, _ = self.server.accept()
        except OSError:
            pass

    def send(self, data):
        self.client.sendall(data)

    def close(self):
        if self.client:
            self.client.close()
        self.server.close()


def test_reads_a_tcp_bridge_and_reconnects_after_it_restarts():
    bridge = Bridge()
    port = bridge.port
    lines, on_line = collect()
    source = LineSource(f'socket://127.0.0.1:{port}', on_line, backoff=0.2).start()
    try:
        assert wait_for(lambda: bridge.client is not None and source.state == 'connected')
        time.sleep(0.3)                         # pyserial flushes input while it opens
        bridge.send(b'{"tag":"1","links":[]}\n{"tag":"2"')
        bridge.send(b',"links":[]}\n')
        assert wait_for(lambda: len(lines) == 2)
        assert lines[1][0] == '{"tag":"2","links":[]}'
        bridge.close()                          # the bridge goes away
        assert wait_for(lambda: source.state == 'disconnected')
        bridge = Bridge(port)                   # and comes back on the same port
        assert wait_for(lambda: bridge.client is not None and source.state == 'connected')
        time.sleep(0.3)
        bridge.send(b'back\n')
        assert wait_for(lambda: lines[-1][0] == 'back')
        assert source.counts['reconnects'] >= 1
    finally:
        source.stop()
        bridge.close()


def test_a_failing_line_handler_does_not_stop_reading():
    master, slave = os.openpty()
    tty.setraw(slave)
    seen = []

    def handler(line, stamp):
        seen.append(line)
        if line == 'bad':
            raise RuntimeError('consumer bug')

    source = LineSource(os.ttyname(slave), handler).start()
    try:
        assert wait_for(lambda: source.state == 'connected')
        os.write(master, b'bad\ngood\n')
        assert wait_for(lambda: seen == ['bad', 'good'])
        assert source.counts['handler_errors'] == 1
    finally:
        source.stop()
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize('port', ['/dev/does-not-exist', 'socket://127.0.0.1:1'])
def test_missing_devices_are_retried_without_raising(port):
    source = LineSource(port, lambda line, stamp: None, backoff=0.1).start()
    try:
        assert wait_for(lambda: source.counts['io_errors'] >= 3)
        assert source.state == 'disconnected' and source.last_error
    finally:
        source.stop()
