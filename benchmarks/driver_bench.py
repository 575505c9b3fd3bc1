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
How fast the driver reads: lines/s and CPU per 1,000 lines, over TCP and a pty.

A child process floods a transport with ``count`` copies of one device line as fast as the
transport takes them; this process reads them with the driver's own path
(:class:`~epp_ros.uwb.source.LineSource` and :class:`~epp_ros.uwb.decoder.LineDecoder`).
The child's CPU is not counted. No ROS.
"""
from dataclasses import dataclass
import os
import socket
import subprocess
import sys
import threading
import time
import tty

from epp_ros.uwb.decoder import LineDecoder
from epp_ros.uwb.source import LineSource

__all__ = ['measure_reading', 'run_driver_bench', 'DriverReport', 'run', 'TRANSPORTS']

TRANSPORTS = ('tcp', 'pty')
DEFAULT_LINE = '{"tag":"1","links":[{"A":"1782","R":"2.300"},{"A":"1783","R":"4.125"}]}'

_WRITER = """
import os, socket, sys
fd, kind, count, line = int(sys.argv[1]), sys.argv[2], int(sys.argv[3]), sys.argv[4]
data = (line + "\\r\\n").encode() * count
if kind == "tcp":
    conn, _ = socket.socket(fileno=fd).accept()
    conn.sendall(data)
    conn.recv(1)
else:
    os.set_blocking(fd, True)
    view = memoryview(data)
    while view:
        view = view[os.write(fd, view[:65536]):]
    sys.stdin.read()
"""


def _transport(kind):
    """(port to read, fd to hand to the writer, things to close)."""
    if kind == 'tcp':
        server = socket.create_server(('127.0.0.1', 0))
        return f'socket://127.0.0.1:{server.getsockname()[1]}', server.fileno(), [server]
    master, slave = os.openpty()
    tty.setraw(slave)
    return os.ttyname(slave), master, [master, slave]


def measure_reading(transport='tcp', count=20000, line=DEFAULT_LINE, protocol='json',
                    timeout=300.0):
    r"""
    Read ``count`` lines flooded through ``transport``; how fast, at what CPU cost.

    Parameters
    ----------
    transport : str
        'tcp' (``socket://``, the WiFi bridge path) or 'pty' (the serial path).
    count : int
        Lines written.
    line : str
        The device line (written with ``\r\n``).
    protocol : str
        Decoder protocol for the lines.
    timeout : float
        Longest wait for every line, seconds.

    Returns
    -------
    dict
        ``lines``, ``seconds`` (first byte written to last line decoded), ``lines_per_s``,
        ``cpu_ms_per_1000_lines`` (this process: reader thread and decoder), ``reads``.

    """
    port, fd, owned = _transport(transport)
    decoder = LineDecoder(protocol)
    done = threading.Event()

    def on_line(text, stamp, _peer):
        decoder.decode(text)
        if decoder.counts['lines'] >= count:
            done.set()

    source = LineSource(port, on_line, max_line=max(4096, 2 * len(line)))
    cpu, started = time.process_time(), time.monotonic()
    source.start()
    writer = subprocess.Popen([sys.executable, '-c', _WRITER, str(fd), transport, str(count),
                               line], pass_fds=(fd,), stdin=subprocess.PIPE)
    try:
        finished = done.wait(timeout)
        seconds, cpu = time.monotonic() - started, time.process_time() - cpu
    finally:
        source.stop()
        writer.stdin.close()
        writer.wait(10)
        for item in owned:
            if isinstance(item, int):
                os.close(item)
            else:
                item.close()
    lines = decoder.counts['lines']
    return {'transport': transport, 'lines': lines, 'complete': finished,
            'seconds': seconds, 'lines_per_s': lines / seconds,
            'cpu_ms_per_1000_lines': 1e6 * cpu / max(lines, 1),
            'reads': source.counts['reads']}


def run_driver_bench(count=20000, transports=TRANSPORTS):
    """One row per transport (see :func:`measure_reading`)."""
    return [measure_reading(kind, count) for kind in transports]


@dataclass
class DriverReport:
    """The report of ``dev.py bench driver``: :func:`measure_reading`'s dict per transport."""

    rows: list
    suite: str = 'driver'


def run(count=20000, transports=TRANSPORTS):
    """Measure every transport; the :class:`DriverReport`."""
    return DriverReport(run_driver_bench(count, transports))


if __name__ == '__main__':
    # reports imports this module; as a script, this one imports it only now: no circle
    from benchmarks.reports import driver_table
    print(driver_table(run_driver_bench(int(sys.argv[1]) if len(sys.argv) > 1 else 20000)))
