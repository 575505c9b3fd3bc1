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

"""The transport against a real pseudo-terminal and a real TCP socket."""
import os
import socket
import threading
import time
import tty

from epp_ros.uwb.source import LineSource, LineSplitter
import pytest


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


def ignore(line, stamp, peer):
    """Take a line and do nothing with it."""


def collect():
    lines = []
    return lines, lambda line, stamp, peer: lines.append((line, stamp))


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

    def handler(line, stamp, peer):
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
    source = LineSource(port, ignore, backoff=0.1).start()
    try:
        assert wait_for(lambda: source.counts['io_errors'] >= 3)
        assert source.state == 'disconnected' and source.last_error
    finally:
        source.stop()


MESSAGES = [b'{"links":[{"A":"B82","R":"2.3"}]}', b'{"links":[{"A":"}{\\"","R":"1"}]}',
            b'{"id":1,"range":[0,0,30,0,0,0,0,0]}']
PREAMBLE = b'GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n'


def test_splitter_frames_concatenated_json_however_it_is_cut():
    from hypothesis import given, settings, strategies as st

    stream = PREAMBLE + b''.join(MESSAGES * 3)
    expected = ['GET / HTTP/1.1', 'Host: 127.0.0.1', 'Connection: close'] + \
        [m.decode() for m in MESSAGES * 3]

    @settings(max_examples=100, deadline=None)
    @given(cuts=st.lists(st.integers(0, len(stream)), max_size=20))
    def check(cuts):
        splitter = LineSplitter()
        lines = []
        bounds = [0, *sorted(cuts), len(stream)]
        for start, end in zip(bounds, bounds[1:]):
            lines += splitter.feed(stream[start:end])
        assert lines == expected and splitter.overlong == 0

    check()


def test_splitter_splits_objects_on_one_line_and_recovers_after_an_overlong_one():
    splitter = LineSplitter(max_line=64)
    assert splitter.feed(b'{"a":1}{"b":"}"}\r\n{"c":2}\n') == ['{"a":1}', '{"b":"}"}', '{"c":2}']
    assert splitter.feed(b'mc 07 0000 a0:0\n') == ['mc 07 0000 a0:0']
    assert splitter.feed(b'{"x":"' + b'y' * 100) == [] and splitter.overlong == 1
    assert splitter.feed(b'"}{"d":3}') == ['{"d":3}']        # resynchronised on the next object


def test_a_listening_source_serves_several_tags_that_write_json_without_newlines():
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    lines, on_line = collect()
    from epp_ros.uwb.source import open_source
    source = open_source(f'tcp-listen://127.0.0.1:{port}', on_line, backoff=0.1).start()
    clients = []
    try:
        assert wait_for(lambda: source.state == 'listening')
        for _ in range(2):
            clients.append(socket.create_connection(('127.0.0.1', port), timeout=5))
        assert wait_for(lambda: source.clients == 2 and source.state == 'connected')
        clients[0].sendall(PREAMBLE + MESSAGES[0])
        clients[1].sendall(MESSAGES[2][:10])
        clients[0].sendall(MESSAGES[1])
        clients[1].sendall(MESSAGES[2][10:] + MESSAGES[2])
        assert wait_for(lambda: len(lines) == 7, 10)
        got = [line for line, _ in lines]
        assert got[:3] == ['GET / HTTP/1.1', 'Host: 127.0.0.1', 'Connection: close']
        assert sorted(got[3:]) == sorted(m.decode() for m in
                                         [MESSAGES[0], MESSAGES[1], MESSAGES[2], MESSAGES[2]])
        clients.pop(0).close()
        assert wait_for(lambda: source.clients == 1 and source.counts['disconnects'] == 1)
        assert source.counts['connections'] == 2 and source.state == 'connected'
    finally:
        for client in clients:
            client.close()
        source.stop()
    with pytest.raises(OSError):                 # nothing listens once stopped
        socket.create_connection(('127.0.0.1', port), timeout=1).close()


def free_local_port():
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        return probe.getsockname()[1]


def test_silent_clients_never_lock_a_listening_port_out():
    """8 half-open clients: a tag that reconnects takes the place of the silent longest."""
    from epp_ros.uwb.source import ListenSource
    port = free_local_port()
    peers, closed = [], []
    source = ListenSource(f'tcp-listen://127.0.0.1:{port}',
                          lambda line, stamp, peer: peers.append((peer, line)),
                          max_clients=8, on_closed=closed.append).start()
    silent = []
    try:
        assert wait_for(lambda: source.state == 'listening')
        for _ in range(8):
            silent.append(socket.create_connection(('127.0.0.1', port), timeout=5))
        assert wait_for(lambda: source.clients == 8)
        with socket.create_connection(('127.0.0.1', port), timeout=5) as tag:
            tag.sendall(b'back again\n')
            assert wait_for(lambda: [line for _, line in peers] == ['back again'])
            assert source.counts['evicted'] == 1 and source.clients == 8
            assert closed == [1]                 # the first, silent longest, made room
            assert peers[0][0] == 9              # the newcomer's own name
    finally:
        for client in silent:
            client.close()
        source.stop()


def test_a_client_silent_for_the_idle_timeout_is_closed():
    from epp_ros.uwb.source import ListenSource
    port = free_local_port()
    closed = []
    source = ListenSource(f'tcp-listen://127.0.0.1:{port}', ignore, idle_timeout=0.5,
                          on_closed=closed.append).start()
    try:
        assert wait_for(lambda: source.state == 'listening')
        with socket.create_connection(('127.0.0.1', port), timeout=5) as quiet:
            assert wait_for(lambda: source.counts['idle_closed'] == 1, 10)
            assert closed == [1] and source.clients == 0 and source.state == 'listening'
            assert quiet.recv(16) == b''          # closed on our side
    finally:
        source.stop()


def test_a_listening_source_binds_to_the_given_address_only():
    from epp_ros.uwb.source import ListenSource
    with socket.socket() as probe:
        probe.bind(('127.0.0.1', 0))
        port = probe.getsockname()[1]
    source = ListenSource(f'tcp-listen://127.0.0.1:{port}', ignore).start()
    try:
        assert wait_for(lambda: source.state == 'listening')
        with socket.socket() as other:        # the same port on another address is free
            other.bind(('127.0.0.2', port))
        blocker = ListenSource(f'tcp-listen://127.0.0.1:{port}', ignore,
                               backoff=0.1).start()
        assert wait_for(lambda: blocker.counts['io_errors'] >= 2)
        assert blocker.state == 'disconnected' and blocker.last_error
        blocker.stop()
    finally:
        source.stop()
    with pytest.raises(ValueError):
        ListenSource('tcp-listen://:80', ignore)


def test_tcp_reads_take_what_the_socket_holds_and_report_the_backlog():
    bridge = Bridge()
    lines, on_line = collect()
    source = LineSource(f'socket://127.0.0.1:{bridge.port}', on_line).start()
    line = b'{"tag":"1","links":[{"A":"1782","R":"2.300"}]}\r\n'
    count = 20000
    try:
        assert wait_for(lambda: bridge.client is not None and source.state == 'connected')
        bridge.send(line * count)
        assert wait_for(lambda: len(lines) == count, 60)
        # Bulk reads: far fewer reads than lines (one byte a read would be 50 a line).
        assert source.counts['reads'] < count / 4
        assert source.counts['bytes'] == len(line) * count
        assert source.backlog >= 0 and source.newest_line == lines[-1][1]
    finally:
        source.stop()
        bridge.close()
