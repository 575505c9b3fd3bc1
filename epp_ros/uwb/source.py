"""Byte streams from serial ports or WiFi-TCP bridges, as lines, reconnecting forever.

One code path for both transports: pyserial's ``serial_for_url`` opens ``/dev/ttyUSB0``
(with a baud rate) or ``socket://host:port``. Bytes are split into lines with a bounded
buffer; over-long lines are discarded and counted; bytes that are not UTF-8 are replaced.
"""
import threading
import time
from collections import Counter

import serial

__all__ = ['LineSplitter', 'LineSource']


class LineSplitter:
    """Split a byte stream into text lines, keeping at most ``max_line`` bytes pending.

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

    def feed(self, data):
        """Add bytes; return the non-empty lines they complete (str, line ends stripped)."""
        lines = []
        parts = bytes(data).split(b'\n')
        for index, part in enumerate(parts):
            complete = index < len(parts) - 1
            if self._discarding:
                self._discarding = not complete   # an over-long line runs to its newline
                continue
            self._pending += part
            if len(self._pending) > self.max_line:
                self.overlong += 1
                self._pending.clear()
                self._discarding = not complete
                continue
            if complete:
                line = self._pending.decode('utf-8', errors='replace').strip('\r\x00 \t')
                self._pending.clear()
                if line:
                    lines.append(line)
        return lines

    def reset(self):
        """Forget a partial line (after a reconnect its rest never comes)."""
        self._pending.clear()
        self._discarding = False


class LineSource:
    """Read lines from one port in a thread, reconnecting with backoff, never raising.

    Parameters
    ----------
    port : str
        Device path or pyserial URL.
    on_line : callable(str, float)
        Called from the reader thread with each line and its receive time
        (``time.time()``, seconds).
    baud : int
        For serial devices.
    max_line : int
        Longest line kept, bytes.
    backoff : float
        Longest wait between reconnection attempts, seconds (waits double from 0.05 s).
    opener : callable
        ``serial.serial_for_url`` by default.

    Attributes
    ----------
    state : str
        ``connecting``, ``connected`` or ``disconnected``.
    counts : collections.Counter
        ``lines``, ``bytes``, ``connections``, ``reconnects``, ``io_errors``,
        ``handler_errors``; the splitter counts ``overlong`` lines.
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
        self.last_error = ''
        self._stop = threading.Event()
        self._thread = None
        self._connection = None

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

    def _connect_and_read(self):
        """Connect (with backoff) and read until the port fails or we are stopped."""
        wait = 0.05
        while not self._stop.is_set():
            try:
                connection = self.opener(self.port, baudrate=self.baud, timeout=0.05)
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
                self._read_until_failure(connection)
            finally:
                _close_quietly(connection)

    def _read_until_failure(self, connection):
        while not self._stop.is_set():
            try:
                data = connection.read(max(1, connection.in_waiting))
            except (serial.SerialException, OSError, TypeError, AttributeError) as exc:
                # pyserial raises TypeError/AttributeError when a port is closed under it.
                self._note_failure(exc)
                return
            if not data:
                continue
            received = time.time()
            self.counts['bytes'] += len(data)
            for line in self.splitter.feed(data):
                self.counts['lines'] += 1
                try:
                    self.on_line(line, received)
                except Exception as exc:  # noqa: BLE001 - a consumer's bug must not stop I/O
                    self.counts['handler_errors'] += 1
                    self.last_error = f'line handler: {exc!r}'

    def _note_failure(self, exc):
        if not self._stop.is_set():
            self.counts['io_errors'] += 1
            self.state = 'disconnected'
            self.last_error = str(exc) or type(exc).__name__


def _close_quietly(connection):
    try:
        connection.close()
    except Exception:   # noqa: BLE001 - closing a vanished port may fail in any way
        pass
