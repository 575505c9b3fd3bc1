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
Impersonating the UWB hardware: device lines per ranging cycle, and where they go.

A ranging cycle's (p, m) ranges become the lines the real devices would print, in any format
of :data:`epp_ros.uwb.formats.FORMATS` (each format's ``emit``). Formats that name the tag
put every tag on one channel; formats that do not need one channel per tag, as on the real
rig where each tag has its own serial port or WiFi bridge; formats that name no device at
all need one channel per tag-anchor pair. A channel is a pseudo-terminal
(:class:`PtyOutput`) or a TCP server like the ESP8266 bridge (:class:`TcpOutput`).

Formats that report anchor-anchor ranges (``LineFormat.emit_anchors``: TREK1000 ``ma``
lines) also print rounds of them, on the first channel (the gateway anchor's): a burst of
:data:`SURVEY_BURST` rounds at start-up, before the boom moves, then one about every
second (:func:`anchor_rounds`, :func:`anchor_lines`).
"""
from collections import Counter
import os
import socket
import threading
import time
import tty

from epp_ros.uwb.formats import Cycle, FORMATS
from epp_ros.uwb.formats.trek import RAW_BIAS
import numpy as np

__all__ = ['TAG_NAMING', 'channel_count', 'channel_devices', 'cycle_lines', 'corrupt',
           'PtyOutput', 'TcpOutput', 'SURVEY_BURST', 'ANCHOR_ROUND_PERIOD', 'anchor_rounds',
           'anchor_lines', 'reports_anchor_ranges']

#: Range bias of the emulated TREK1000 raw (``mr``) lines, metres.
TREK_RAW_BIAS = RAW_BIAS

#: Whether a protocol's lines name the tag.
TAG_NAMING = {name: line_format.names_tag for name, line_format in FORMATS.items()}


def _format(protocol):
    try:
        return FORMATS[protocol]
    except KeyError:
        raise ValueError(f'unknown protocol {protocol!r}') from None


def channel_count(protocol, n_tags, n_anchors=1):
    """Channels (ports) a protocol needs for ``n_tags`` tags and ``n_anchors`` anchors."""
    line_format = _format(protocol)
    if not line_format.names_anchor:
        return n_tags * n_anchors
    return 1 if line_format.names_tag else n_tags


def channel_devices(protocol, config):
    """Per channel, the (tag id, anchor id) its lines leave unnamed (None where named)."""
    line_format = _format(protocol)
    if line_format.names_tag and line_format.names_anchor:
        return [(None, None)]
    if line_format.names_anchor:
        return [(tag, None) for tag in config.tag_ids]
    return [(tag, anchor) for tag in config.tag_ids for anchor in config.anchor_ids]


def cycle_lines(config, ranges, protocol, sequence=0, rx_power=-80.0):
    """
    Device lines of one ranging cycle.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
        The pump: device ids and anchor positions.
    ranges : ndarray, shape (p, m)
        Metres; NaN links are not reported.
    protocol : str
        A name in :data:`epp_ros.uwb.formats.FORMATS`.
    sequence : int
        Cycle number (some formats carry it).
    rx_power : float
        dBm, for the formats that print it.

    Returns
    -------
    list of (channel, line)
        ``channel`` as :func:`channel_devices` numbers them.

    Raises
    ------
    ValueError
        For an unknown protocol, or ids or ranges the format cannot carry.

    """
    line_format = _format(protocol)
    cycle = Cycle(sequence, dict(zip(config.anchor_ids, config.anchor_positions)), rx_power)
    m = len(config.anchor_ids)
    lines = []
    for row, tag in enumerate(config.tag_ids):
        measured = {config.anchor_ids[j]: float(ranges[row, j])
                    for j in np.flatnonzero(np.isfinite(ranges[row]))}
        if not measured:
            continue
        if not line_format.names_anchor:
            for anchor, value in measured.items():
                channel = row * m + config.anchor_ids.index(anchor)
                lines += [(channel, line) for line in line_format.emit(tag, {anchor: value},
                                                                       cycle)]
            continue
        channel = 0 if line_format.names_tag else row
        lines += [(channel, line) for line in line_format.emit(tag, measured, cycle)]
    return lines


#: Rounds of anchor-anchor ranges at start-up, before the first ranging cycle's lines.
SURVEY_BURST = 10
#: Seconds between rounds of anchor-anchor ranges after the start-up burst.
ANCHOR_ROUND_PERIOD = 1.0


def anchor_rounds(cycle, rate):
    """
    Return how many rounds of anchor-anchor ranges come with ranging cycle ``cycle``.

    Parameters
    ----------
    cycle : int
        Ranging cycle number, from 0.
    rate : float
        Ranging cycles per second.

    Returns
    -------
    int
        :data:`SURVEY_BURST` with cycle 0, then 1 about every :data:`ANCHOR_ROUND_PERIOD`
        seconds, else 0.

    """
    if cycle == 0:
        return SURVEY_BURST
    return int(cycle % max(1, round(rate * ANCHOR_ROUND_PERIOD)) == 0)


def reports_anchor_ranges(protocol):
    """Whether a protocol's devices print anchor-anchor ranges."""
    return _format(protocol).emit_anchors is not None


def anchor_lines(config, ranges, protocol, sequence=0):
    """
    Device lines of one round of anchor-anchor ranges.

    Parameters
    ----------
    config : epp_ros.app.config.PumpConfig
        The pump: anchor ids and positions.
    ranges : ndarray, shape (m, m)
        Metres, row the measuring anchor; NaN pairs are not reported.
    protocol : str
        A name in :data:`epp_ros.uwb.formats.FORMATS`.
    sequence : int
        Cycle number (some formats carry it).

    Returns
    -------
    list of (channel, line)
        On channel 0; none for a format without anchor-anchor ranges.

    Raises
    ------
    ValueError
        For an unknown protocol, or ids or ranges the format cannot carry.

    """
    line_format = _format(protocol)
    if line_format.emit_anchors is None:
        return []
    ids = config.anchor_ids
    rows, columns = np.nonzero(np.isfinite(ranges))
    measured = {(ids[i], ids[j]): float(ranges[i, j]) for i, j in zip(rows, columns)}
    cycle = Cycle(sequence, dict(zip(ids, config.anchor_positions)))
    return [(0, line) for line in line_format.emit_anchors(measured, cycle)]


def corrupt(line, rng):
    """Return a damaged version of ``line`` (bytes), as noisy links and firmware produce."""
    data = line.encode()
    kind = rng.integers(4)
    if kind == 0:                                   # cut short
        return data[:rng.integers(len(data))]
    if kind == 1:                                   # binary noise instead of a line
        return rng.integers(0, 256, rng.integers(1, 64), dtype=np.uint8).tobytes()
    if kind == 2:                                   # a flipped byte
        position = rng.integers(len(data))
        return data[:position] + bytes([int(rng.integers(0, 256))]) + data[position + 1:]
    return data + data[:rng.integers(len(data))]    # a repeated fragment


class PtyOutput:
    """
    A pseudo-terminal that a driver opens like a USB-UART device.

    Parameters
    ----------
    link : str, optional
        A symlink to create to the device (like a udev rule's stable name), so that a
        driver finds a restarted emulator at the same path.

    Attributes
    ----------
    path : str
        What to open: the link if given, else the pty device.
    counts : collections.Counter
        ``written``, ``truncated`` and ``dropped`` writes (the reader fell behind).

    """

    def __init__(self, link=None):
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        self.device = os.ttyname(self._slave)
        self.link = link
        if link:
            if os.path.lexists(link):
                os.unlink(link)
            os.symlink(self.device, link)
        self.path = link or self.device
        self.counts = Counter()

    def write(self, data):
        try:
            sent = os.write(self._master, data)
        except BlockingIOError:
            self.counts['dropped'] += 1
            return
        # A full buffer takes part of a line, as a real UART overrun cuts one.
        self.counts['written' if sent == len(data) else 'truncated'] += 1

    def close(self):
        for fd in (self._master, self._slave):
            try:
                os.close(fd)
            except OSError:
                pass
        if self.link and os.path.islink(self.link):
            os.unlink(self.link)


class TcpOutput:
    """
    A TCP server on loopback that streams lines to every client, like the ESP8266 bridge.

    New clients get data 0.2 s after they connect: pyserial's ``socket://`` discards what
    arrives while it opens.
    """

    def __init__(self, host, port, grace=0.2):
        self._server = socket.create_server((host, port))      # SO_REUSEADDR on POSIX
        self.host, self.port = self._server.getsockname()[:2]
        self.path = f'socket://{self.host}:{self.port}'
        self.grace = grace
        self.counts = Counter()
        self._clients = []
        self._lock = threading.Lock()
        self._closed = threading.Event()
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while not self._closed.is_set():
            try:
                client, _ = self._server.accept()
            except OSError:
                return
            client.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client.settimeout(0.05)          # a stalled client must not stall the pump
            with self._lock:
                self._clients.append((client, time.monotonic() + self.grace))

    def write(self, data):
        now = time.monotonic()
        with self._lock:
            for entry in list(self._clients):
                client, ready = entry
                if now < ready:
                    continue
                try:
                    client.sendall(data)
                    self.counts['written'] += 1
                except OSError:                    # gone or stalled: drop the client
                    self._clients.remove(entry)
                    client.close()
                    self.counts['dropped'] += 1

    def close(self):
        self._closed.set()
        self._server.close()
        with self._lock:
            for client, _ in self._clients:
                client.close()
            self._clients.clear()
