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
Byte streams from serial ports, WiFi-TCP bridges and WiFi tags, as lines, never giving up.

Three kinds of port:

- a serial device (``/dev/ttyUSB0``, or any pyserial URL): pyserial's ``serial_for_url``,
  reading what the driver has buffered (``in_waiting``);
- ``socket://host:port``: we connect to a bridge (ESP8266 firmware that serves its UART on a
  TCP port) and read the socket itself, whatever it holds, up to 64 KiB a call;
- ``tcp-listen://address:port``: devices connect to us (the Makerfabs ESP32 UWB tag is a TCP
  client); bound to exactly the address given, several clients at once, each framed on its
  own and named to the line handler (``peer``), so that each is decoded on its own. A
  client silent for ``idle_timeout`` is closed, TCP keepalive finds half-open ones, and
  when every place is taken a newcomer takes the place of the client silent longest: a
  tag that drops off WiFi and reconnects always gets back in.

:class:`LineSplitter` frames bytes into lines: at newlines, and between JSON objects written
back to back with no newline (``{...}{...}``), so that a device that never ends a line is
read message by message. Over-long lines are discarded and counted; bytes that are not
UTF-8 are replaced. Sources reconnect (or listen again) forever with backoff.
"""
from collections import Counter
import fcntl
import re
import selectors
import socket
import struct
import termios
import threading
import time

import serial

__all__ = ['LineSplitter', 'LineSource', 'ListenSource', 'open_source', 'READ_SIZE']

#: Bytes asked of a socket per read.
READ_SIZE = 65536
#: Seconds a read waits for data (bounds how late a stop request is seen).
READ_TIMEOUT = 0.05
#: Seconds a listening port's client may send nothing before it is closed (tags send lines
#: at 1-50 Hz; one that stops has gone, or reconnected on another socket).
IDLE_TIMEOUT = 10.0
#: TCP keepalive of accepted clients, s: first probe after this much silence, then probes
#: this often, this many unanswered before the connection is dropped.
KEEPALIVE = (5, 2, 3)

_TOKENS = re.compile(rb'[{}"\\]')
_CONCATENATED = re.compile(rb'\}\s*\{')


class LineSplitter:
    """
    Split a byte stream into text lines, keeping at most ``max_line`` bytes pending.

    Lines end at a newline, or where a top-level JSON object closes when another follows
    on the same line or no newline has come yet (a device writing ``{...}{...}``). Braces
    and quotes are tracked across reads, inside JSON strings too.

    Attributes
    ----------
    overlong : int
        Lines discarded because they exceeded ``max_line`` bytes.

    """

    def __init__(self, max_line=4096):
        self.max_line = int(max_line)
        self.overlong = 0
        self._pending = bytearray()
        self._discarding = False
        self._reset_scan()

    def _reset_scan(self):
        self._scan_position = 0     # bytes of _pending already scanned for JSON structure
        self._depth = 0
        self._in_string = False
        self._skip_to = 0           # the byte after a backslash inside a string

    def feed(self, data):
        """Add bytes; return the non-empty lines they complete (str, line ends stripped)."""
        lines = []
        parts = bytes(data).split(b'\n')
        last = len(parts) - 1
        for index, part in enumerate(parts):
            complete = index < last
            if self._discarding:
                part = self._resync(part, complete)
                if part is None:
                    continue
            self._pending += part
            if complete:
                self._finish_line(lines)
            else:
                if b'}' in part:
                    self._emit_objects(lines)
                if len(self._pending) > self.max_line:
                    self._drop_pending()
                    self._discarding = True
        return lines

    def reset(self):
        """Forget a partial line (after a reconnect its rest never comes)."""
        self._pending.clear()
        self._discarding = False
        self._reset_scan()

    def _resync(self, part, complete):
        """Return the rest of ``part`` after an over-long line ended, None while it goes on."""
        if complete:
            self._discarding = False        # an over-long line runs to its newline ...
            return None
        match = _CONCATENATED.search(part)  # ... or to the next JSON object
        if match is None:
            return None
        self._discarding = False
        return part[match.end() - 1:]

    def _drop_pending(self):
        self.overlong += 1
        self._pending.clear()
        self._reset_scan()

    def _finish_line(self, lines):
        """Handle a newline: emit what is pending (split between JSON objects) and reset."""
        if self._scan_position or self._depth or _CONCATENATED.search(self._pending):
            self._emit_objects(lines)
        self._emit(lines, self._pending)
        self._pending.clear()
        self._reset_scan()

    def _emit_objects(self, lines):
        """Emit pending text up to each top-level JSON object that closed."""
        pending = self._pending
        depth, in_string, skip_to = self._depth, self._in_string, self._skip_to
        cut = start = 0
        for match in _TOKENS.finditer(pending, self._scan_position):
            position = match.start()
            if position < skip_to:
                continue
            byte = pending[position]
            if in_string:
                if byte == 0x5C:                    # backslash: skip the escaped byte
                    skip_to = position + 2
                elif byte == 0x22:
                    in_string = False
            elif byte == 0x7B:
                depth += 1
                start = position if depth == 1 else start
            elif byte == 0x7D and depth:
                depth -= 1
                if not depth:
                    self._emit_object(lines, pending, cut, start, position + 1)
                    cut = position + 1
            elif byte == 0x22 and depth:            # strings count inside objects only
                in_string = True
        del pending[:cut]
        self._scan_position = len(pending)
        self._depth, self._in_string, self._skip_to = depth, in_string, max(0, skip_to - cut)

    def _emit_object(self, lines, pending, cut, start, end):
        """Emit ``pending[cut:end]``; if too long, count it and keep the object alone."""
        if end - cut > self.max_line and end - start <= self.max_line:
            self.overlong += 1
            cut = start
        self._emit(lines, pending[cut:end])

    def _emit(self, lines, data):
        if len(data) > self.max_line:
            self.overlong += 1
            return
        line = bytes(data).decode('utf-8', errors='replace').strip('\r\x00 \t')
        if line:
            lines.append(line)


def _fionread(fileno):
    """Bytes waiting in the kernel's input buffer of a socket or tty, 0 if unknown."""
    try:
        buffer = fcntl.ioctl(fileno, termios.FIONREAD, b'\0\0\0\0')
        return struct.unpack('i', buffer)[0]
    except (OSError, ValueError):
        return 0


class _SerialStream:
    """A pyserial port: reads what its driver has buffered."""

    def __init__(self, connection):
        self.connection = connection

    def read(self):
        return self.connection.read(max(1, self.connection.in_waiting))

    def backlog(self):
        try:
            return int(self.connection.in_waiting)
        except Exception:   # noqa: BLE001 - a vanished port fails in any way; read reports it
            return 0

    def close(self):
        _close_quietly(self.connection)


class _SocketStream:
    """A connected TCP socket: reads whatever it holds, up to READ_SIZE bytes."""

    def __init__(self, sock):
        self.sock = sock
        sock.settimeout(READ_TIMEOUT)

    def read(self):
        try:
            data = self.sock.recv(READ_SIZE)
        except TimeoutError:
            return b''
        if not data:
            raise ConnectionError('connection closed by the peer')
        return data

    def backlog(self):
        return _fionread(self.sock.fileno())

    def close(self):
        _close_quietly(self.sock)


def _tcp_address(url):
    """(host, port) of ``socket://host:port[?options]``, ValueError if malformed."""
    address = url[len('socket://'):].split('?', 1)[0].split('/', 1)[0]
    host, _, port = address.rpartition(':')
    if not host or not port.isdigit():
        raise ValueError(f'expected socket://HOST:PORT, got {url!r}')
    return host.strip('[]'), int(port)


class LineSource:
    """
    Read lines from one port in a thread, reconnecting with backoff, never raising.

    Parameters
    ----------
    port : str
        Device path, pyserial URL, or ``socket://host:port``.
    on_line : callable(str, float, peer)
        Called from the reader thread with each line, its receive time (``time.time()``,
        seconds) and the client it came from (None for a port with one peer).
    baud : int
        For serial devices.
    max_line : int
        Longest line kept, bytes.
    backoff : float
        Longest wait between reconnection attempts, seconds (waits double from 0.05 s).
    opener : callable
        ``serial.serial_for_url`` by default; another opener is used for every port.

    Attributes
    ----------
    state : str
        ``connecting``, ``connected`` or ``disconnected``.
    counts : collections.Counter
        ``lines``, ``bytes``, ``reads``, ``connections``, ``reconnects``, ``io_errors``,
        ``handler_errors``; the splitter counts ``overlong`` lines.
    backlog : int
        Bytes waiting in the input buffer after the latest read.
    newest_line : float or None
        Receive time (``time.time()``) of the newest line.
    last_error : str

    """

    def __init__(self, port, on_line, baud=115200, max_line=4096, backoff=1.0,
                 opener=serial.serial_for_url):
        self.port = port
        self.on_line = on_line
        self.baud = int(baud)
        self.backoff = float(backoff)
        self.opener = opener
        self.splitter = LineSplitter(max_line)
        self.state = 'connecting'
        self.counts = Counter()
        self.backlog = 0
        self.newest_line = None
        self.last_error = ''
        self._stop = threading.Event()
        self._thread = None

    @property
    def overlong(self):
        """Lines discarded for exceeding ``max_line``."""
        return self.splitter.overlong

    @property
    def clients(self):
        """Return the number of connected peers (1 while connected)."""
        return int(self.state == 'connected')

    def start(self):
        """Start reading in a daemon thread; returns self."""
        self._thread = threading.Thread(target=self._run, name=f'uwb:{self.port}', daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout=2.0):
        """Stop reading and close the port."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)

    def _run(self):
        while not self._stop.is_set():
            try:
                self._connect_and_read()
            except Exception as exc:  # noqa: BLE001 - whatever breaks, retry the port
                self.counts['unexpected_errors'] += 1
                self._note_failure(exc)
                self._stop.wait(self.backoff)
        self.state = 'disconnected'

    def _open(self):
        """Return the port as a stream (a socket for ``socket://`` unless an opener was given)."""
        if self.port.startswith('socket://') and self.opener is serial.serial_for_url:
            return _SocketStream(socket.create_connection(_tcp_address(self.port), timeout=2))
        return _SerialStream(self.opener(self.port, baudrate=self.baud, timeout=READ_TIMEOUT))

    def _connect_and_read(self):
        """Connect (with backoff) and read until the port fails or we are stopped."""
        wait = 0.05
        while not self._stop.is_set():
            try:
                stream = self._open()
            except (serial.SerialException, OSError, ValueError) as exc:
                self._note_failure(exc)
                self._stop.wait(wait)
                wait = min(2 * wait, self.backoff)
                continue
            if self.counts['connections']:
                self.counts['reconnects'] += 1
            self.counts['connections'] += 1
            self.state = 'connected'
            wait = 0.05
            self.splitter.reset()
            try:
                self._read_until_failure(stream)
            finally:
                stream.close()

    def _read_until_failure(self, stream):
        while not self._stop.is_set():
            try:
                data = stream.read()
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # pyserial raises TypeError/AttributeError when a port is closed under it.
                self._note_failure(exc)
                return
            if data:
                self.backlog = stream.backlog()
                self._deliver(data)

    def _deliver(self, data, peer=None):
        received = time.time()
        self.counts['bytes'] += len(data)
        self.counts['reads'] += 1
        for line in self.splitter.feed(data):
            self.counts['lines'] += 1
            self.newest_line = received
            try:
                self.on_line(line, received, peer)
            except Exception as exc:  # noqa: BLE001 - a consumer's bug must not stop I/O
                self.counts['handler_errors'] += 1
                self.last_error = f'line handler: {exc!r}'

    def _note_failure(self, exc):
        if not self._stop.is_set():
            self.counts['io_errors'] += 1
            self.state = 'disconnected'
            self.last_error = str(exc) or type(exc).__name__


_LISTEN = re.compile(r'tcp-listen://(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):([0-9]{1,5})')


def listen_url_address(url):
    """(host, port) of ``tcp-listen://host:port``, ValueError without both."""
    match = _LISTEN.fullmatch(url)
    if match is None or not 0 < int(match.group(2)) < 65536:
        raise ValueError(f'expected tcp-listen://ADDRESS:PORT, got {url!r}')
    return match.group(1).strip('[]'), int(match.group(2))


class _Client:
    """A client of a listening port: its framing, its name for the handler, when it spoke."""

    def __init__(self, peer, max_line):
        self.peer = peer
        self.splitter = LineSplitter(max_line)
        self.heard = time.monotonic()


class ListenSource(LineSource):
    """
    Accept devices that connect to us, read each client's lines, listen again if it fails.

    Parameters
    ----------
    port : str
        ``tcp-listen://address:port``; bound to exactly that address.
    on_line : callable(str, float, int)
        As for :class:`LineSource`; lines of all clients, each client framed on its own and
        named by a number (``peer``) that is never reused.
    max_line, backoff
        As for :class:`LineSource`.
    max_clients : int
        Clients served at once; a newcomer beyond them takes the place of the client that
        has been silent longest (counted ``evicted``).
    idle_timeout : float
        Seconds a client may send nothing before it is closed (counted ``idle_closed``).
    on_closed : callable(int), optional
        Called from the reader thread with the ``peer`` of each client closed, for any
        reason.

    Attributes
    ----------
    state : str
        ``connecting``, ``listening`` (bound, no client), ``connected`` (one client or
        more) or ``disconnected`` (cannot bind).
    counts : collections.Counter
        As :class:`LineSource`, plus ``disconnects``, ``idle_closed`` and ``evicted``;
        ``connections`` counts accepted clients.

    """

    def __init__(self, port, on_line, max_line=4096, backoff=1.0, max_clients=8,
                 idle_timeout=IDLE_TIMEOUT, on_closed=None, **_):
        super().__init__(port, on_line, max_line=max_line, backoff=backoff)
        self.address = listen_url_address(port)
        self.max_clients = int(max_clients)
        self.max_line = int(max_line)
        self.idle_timeout = float(idle_timeout)
        self.on_closed = on_closed
        self._clients = {}          # socket -> _Client
        self._overlong_closed = 0
        self._peers = 0

    @property
    def overlong(self):
        return self._overlong_closed + sum(c.splitter.overlong
                                           for c in list(self._clients.values()))

    @property
    def clients(self):
        return len(self._clients)

    def _connect_and_read(self):
        """Bind (with backoff) and serve clients until binding fails or we are stopped."""
        wait = 0.05
        while not self._stop.is_set():
            host, port = self.address
            try:
                server = socket.create_server(
                    (host, port), family=socket.AF_INET6 if ':' in host else socket.AF_INET)
            except OSError as exc:
                self._note_failure(exc)
                self._stop.wait(wait)
                wait = min(2 * wait, self.backoff)
                continue
            wait = 0.05
            try:
                self._serve(server)
            finally:
                for client in list(self._clients):
                    self._drop(client)
                _close_quietly(server)

    def _serve(self, server):
        self.state = 'listening'
        with selectors.DefaultSelector() as selector:
            selector.register(server, selectors.EVENT_READ)
            while not self._stop.is_set():
                for key, _ in selector.select(READ_TIMEOUT):
                    if key.fileobj is server:
                        self._accept(server, selector)
                    else:
                        self._read_client(key.fileobj, selector)
                self._close_idle(selector)

    def _accept(self, server, selector):
        try:
            client, _ = server.accept()
        except OSError as exc:
            self._note_failure(exc)
            return
        if len(self._clients) >= self.max_clients:     # newest wins: a tag that came back
            silent = min(self._clients, key=lambda c: self._clients[c].heard)
            self.counts['evicted'] += 1
            self._close(silent, selector)
        client.setblocking(False)
        _keep_alive(client)
        self._peers += 1
        self._clients[client] = _Client(self._peers, self.max_line)
        selector.register(client, selectors.EVENT_READ)
        self.counts['connections'] += 1
        self.state = 'connected'

    def _close_idle(self, selector):
        """Close the clients that have sent nothing for ``idle_timeout``."""
        now = time.monotonic()
        for client, state in list(self._clients.items()):
            if now - state.heard > self.idle_timeout:
                self.counts['idle_closed'] += 1
                self._close(client, selector)

    def _read_client(self, client, selector):
        try:
            data = client.recv(READ_SIZE)
        except (BlockingIOError, InterruptedError):
            return
        except OSError as exc:
            self.last_error = str(exc) or type(exc).__name__
            data = b''
        if not data:
            self._close(client, selector)
            return
        state = self._clients[client]
        state.heard = time.monotonic()
        self.splitter = state.splitter
        self.backlog = sum(_fionread(c.fileno()) for c in self._clients)
        self._deliver(data, state.peer)

    def _close(self, client, selector):
        selector.unregister(client)
        self._drop(client)

    def _drop(self, client):
        state = self._clients.pop(client, None)
        _close_quietly(client)
        if state is not None:
            self._overlong_closed += state.splitter.overlong
            self.counts['disconnects'] += 1
            if self.on_closed is not None:
                try:
                    self.on_closed(state.peer)
                except Exception as exc:  # noqa: BLE001 - a consumer's bug must not stop I/O
                    self.counts['handler_errors'] += 1
                    self.last_error = f'close handler: {exc!r}'
        if not self._clients and self.state == 'connected':
            self.state = 'listening'


def _keep_alive(client):
    """Turn on TCP keepalive (``KEEPALIVE``), so that a half-open client is found."""
    idle, interval, count = KEEPALIVE
    client.setsockopt(socket.SOL_SOCKET, socket.SO_KEEPALIVE, 1)
    for option, value in (('TCP_KEEPIDLE', idle), ('TCP_KEEPINTVL', interval),
                          ('TCP_KEEPCNT', count)):
        if hasattr(socket, option):             # Linux; elsewhere the system's defaults
            client.setsockopt(socket.IPPROTO_TCP, getattr(socket, option), value)


def open_source(port, on_line, on_closed=None, **options):
    """
    Return a started-later reader for ``port``: :class:`ListenSource` or :class:`LineSource`.

    ``on_closed`` is a listening port's (a port with one peer names it None, and keeps it).
    """
    if port.startswith('tcp-listen://'):
        return ListenSource(port, on_line, on_closed=on_closed, **options)
    return LineSource(port, on_line, **options)


def _close_quietly(connection):
    try:
        connection.close()
    except Exception:   # noqa: BLE001 - closing a vanished port may fail in any way
        pass
