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
Lines of one source -> range records, with protocol auto-detection.

With ``protocol="auto"`` every format's parser is tried on each line until one format has
parsed ``lock_after`` lines; from then on only that parser runs. Records parsed while
detecting are kept, not dropped. Lines that give no range but that a format knows (a
DWM1001 position, a WiFi tag's HTTP preamble) are counted under their label, not as
unparsed. On a port several devices connect to, each client gets its own decoder
(:class:`PeerDecoders`): a stray client cannot decide the protocol of the others.
"""
from collections import Counter
import threading

from epp_ros.uwb.formats import FORMATS, recognised

__all__ = ['LineDecoder', 'PeerDecoders']


class LineDecoder:
    """
    Decode the lines of one source.

    Parameters
    ----------
    protocol : str
        A name in :data:`epp_ros.uwb.formats.FORMATS` or ``"auto"``.
    lock_after : int
        Lines one protocol must parse before auto-detection settles on it.

    Attributes
    ----------
    protocol : str or None
        The protocol in use (None while auto-detection has not settled).
    counts : collections.Counter
        ``lines``, ``parsed`` (lines that gave records), ``unparsed`` (lines no parser
        understood), ``errors`` (broken pieces inside parsed lines), ``records``, and one
        count per label of lines known to carry no range (``position``, ``preamble``).

    """

    def __init__(self, protocol='auto', lock_after=3):
        if protocol != 'auto' and protocol not in FORMATS:
            raise ValueError(f'protocol must be auto or one of {list(FORMATS)}, got {protocol!r}')
        self.protocol = None if protocol == 'auto' else protocol
        self.lock_after = int(lock_after)
        self.counts = Counter()
        self._votes = Counter()

    @property
    def format(self):  # noqa: A003 (public attribute of the API; a property shadows nothing)
        """Return the :class:`~epp_ros.uwb.formats.LineFormat` in use, None while detecting."""
        return FORMATS.get(self.protocol)

    def decode(self, line):
        """Return the records of one line (a tuple, empty when nothing valid was in it)."""
        self.counts['lines'] += 1
        candidates = [self.protocol] if self.protocol else list(FORMATS)
        for name in candidates:
            result = FORMATS[name].parse(line)
            if result is not None and result.records:
                break
        else:
            self.counts[recognised(line, candidates) or 'unparsed'] += 1
            return ()
        if self.protocol is None:
            self._votes[name] += 1
            if self._votes[name] >= self.lock_after:
                self.protocol = name
        self.counts['parsed'] += 1
        self.counts['errors'] += result.errors
        self.counts['records'] += len(result.records)
        return result.records


class PeerDecoders:
    """
    One :class:`LineDecoder` per client of a source, each detecting its own protocol.

    Parameters
    ----------
    protocol, lock_after
        As for :class:`LineDecoder`, for every client.

    Attributes
    ----------
    counts : collections.Counter
        The sum over every client, closed ones included.
    protocol : str or None
        The protocols the connected clients settled on, comma-separated (None: none yet).

    """

    def __init__(self, protocol='auto', lock_after=3):
        LineDecoder(protocol, lock_after)           # refuse a bad name here, not per client
        self._settings = (protocol, lock_after)
        self._decoders = {}                         # peer -> LineDecoder
        self._closed = Counter()
        self._lock = threading.Lock()

    def decoder(self, peer=None):
        """Return the decoder of a client (``peer`` as the source names it)."""
        with self._lock:
            found = self._decoders.get(peer)
            if found is None:
                found = self._decoders[peer] = LineDecoder(*self._settings)
            return found

    def forget(self, peer):
        """Drop a closed client's decoder, keeping its counts."""
        with self._lock:
            gone = self._decoders.pop(peer, None)
            if gone is not None:
                self._closed.update(gone.counts)

    @property
    def counts(self):
        """Return the counts of every client's decoder, summed."""
        with self._lock:
            total = Counter(self._closed)
            for decoder in self._decoders.values():
                total.update(decoder.counts)
        return total

    @property
    def protocol(self):
        """Return the protocols the connected clients use, or None."""
        with self._lock:
            names = sorted({d.protocol for d in self._decoders.values() if d.protocol})
        return ', '.join(names) or None
