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
rosbag2 files without ROS: synthesise, read, evaluate and describe them (``rosbags``).

Bags are standard rosbag2 (metadata version 9, MCAP or sqlite3 storage, explicit QoS per
topic), so that ``ros2 bag play``/``record`` on a full ROS install read and write the same.
Topics: ``/uwb/ranges`` (``sensor_msgs/JointState`` as uwb_driver publishes it; ``effort``
the ranges' ages where known, see ``contract``), ``/arm_posture/ground_truth`` and
``/arm_posture`` (``geometry_msgs/PoseArray``), and optionally ``/uwb/raw``
(``std_msgs/String``, the devices' lines) and ``/uwb/anchor_ranges``
(``sensor_msgs/JointState``, rounds of anchor-anchor ranges, see ``contract``;
:func:`read_anchor_ranges`).
"""
from array import array
import contextlib
from dataclasses import dataclass, field
import os
from pathlib import Path
import time

from epp_ros.app import contract
from epp_ros.app.pipeline import RangePipeline
from epp_ros.core import PostureEstimator
from epp_ros.core.estimation import frame_rmse, joint_errors, pooled_rmse
from epp_ros.core.simulation import RangeNoise, working_cycle
from epp_ros.uwb.emulation import anchor_lines, cycle_lines
import numpy as np
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from rosbags.rosbag2 import Reader, StoragePlugin, Writer, WriterError
from rosbags.typesys import get_typestore, Stores

__all__ = ['BagError', 'RANGES', 'TRUTH', 'POSTURE', 'RAW', 'ANCHOR_RANGES', 'TYPES',
           'synthesize', 'info', 'write_frames', 'evaluate', 'check', 'Damage', 'qos_profile',
           'read_all', 'write_raw', 'read_anchor_ranges', 'BagWriter', 'reindex']

_TOPICS = (contract.RANGES, contract.TRUTH, contract.POSTURE, contract.RAW,
           contract.ANCHOR_RANGES)
RANGES, TRUTH, POSTURE, RAW, ANCHOR_RANGES = (topic.absolute for topic in _TOPICS)
TYPES = {topic.absolute: topic.type for topic in _TOPICS}
STORAGES = {'mcap': StoragePlugin.MCAP, 'sqlite3': StoragePlugin.SQLITE3}
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)


class BagError(Exception):
    """A bag that cannot be used; the message is one line for the user."""


def qos_profile(depth, reliable=True):
    """Return a fully specified QoS profile to store with a connection."""
    infinite = QosTime(sec=0, nsec=0)
    return Qos(history=QosHistory.KEEP_LAST, depth=depth,
               reliability=QosReliability.RELIABLE if reliable else QosReliability.BEST_EFFORT,
               durability=QosDurability.VOLATILE, deadline=infinite, lifespan=infinite,
               liveliness=QosLiveliness.AUTOMATIC, liveliness_lease_duration=infinite,
               avoid_ros_namespace_conventions=False)


#: The QoS each topic is published with (uwb_driver, posture_estimator, uwb_emulator).
TOPIC_QOS = {topic.absolute: qos_profile(topic.depth, topic.reliable) for topic in _TOPICS}


def _header(stamp_ns, frame_id):
    types = TYPESTORE.types
    return types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=int(stamp_ns // 10 ** 9),
                                                   nanosec=int(stamp_ns % 10 ** 9)),
        frame_id=frame_id)


def _ranges_message(stamp_ns, frame_id, names, ranges, ages=None, number=None):
    """
    Return a ``uwb/ranges`` message as the driver publishes it.

    ``ages`` (s, as ``ranges``) fill ``effort``; ``number`` is the frame's, carried last
    (``contract.FRAME_NUMBER``).
    """
    empty = np.zeros(0, dtype=np.float64)
    names, position = list(names), np.asarray(ranges, dtype=np.float64).ravel()
    effort = empty if ages is None else np.asarray(ages, dtype=np.float64).ravel()
    if number is not None:
        names.append(contract.FRAME_NUMBER)
        position = np.append(position, float(number))
        effort = effort if ages is None else np.append(effort, 0.0)
    return TYPESTORE.types[TYPES[RANGES]](
        header=_header(stamp_ns, frame_id), name=names, position=position, velocity=empty,
        effort=effort)


def _anchor_ranges_message(stamp_ns, config, ranges):
    """Return a ``uwb/anchor_ranges`` message of one round (m, m), its finite entries."""
    rows, columns = np.nonzero(np.isfinite(ranges))
    empty = np.zeros(0, dtype=np.float64)
    return TYPESTORE.types[TYPES[ANCHOR_RANGES]](
        header=_header(stamp_ns, config.frame_id),
        name=contract.anchor_range_names(config.anchor_names, rows, columns),
        position=np.asarray(ranges[rows, columns], dtype=np.float64), velocity=empty,
        effort=empty)


def _posture_message(stamp_ns, frame_id, base, joints):
    types = TYPESTORE.types
    poses = [types['geometry_msgs/msg/Pose'](
        position=types['geometry_msgs/msg/Point'](*position),
        orientation=types['geometry_msgs/msg/Quaternion'](*quaternion))
        for position, quaternion in contract.posture_poses(base, joints)]
    return types[TYPES[TRUTH]](header=_header(stamp_ns, frame_id), poses=poses)


def _serialize(message):
    return TYPESTORE.serialize_cdr(message, message.__msgtype__)


class BagWriter:
    """
    A rosbag2 writer with one connection per topic, created on first use.

    Messages go to the storage as they are written (the storage buffers a chunk), so a
    long recording needs no more memory than a short one. ``with`` opens it: a path that
    exists or cannot be written is a :class:`BagError` then, before anything is recorded.
    """

    def __init__(self, path, storage='mcap'):
        if storage not in STORAGES:
            raise BagError(f'storage must be one of {list(STORAGES)}, got {storage!r}')
        if Path(path).exists():
            raise BagError(f'{path} exists already')
        self.path = path
        self.writer = Writer(path, version=9, storage_plugin=STORAGES[storage])
        self.connections = {}

    def __enter__(self):
        try:
            self.writer.open()
        except (OSError, WriterError) as exc:
            raise BagError(f'{self.path}: cannot write: {exc}') from None
        return self

    def __exit__(self, *exc):
        self.writer.close()

    def write(self, topic, stamp_ns, raw, msgtype=None, qos=None):
        if topic not in self.connections:
            self.connections[topic] = self.writer.add_connection(
                topic, msgtype or TYPES[topic], typestore=TYPESTORE,
                offered_qos_profiles=[qos or TOPIC_QOS.get(topic, qos_profile(10))])
        self.writer.write(self.connections[topic], int(stamp_ns), raw)


def synthesize(path, config, duration=60.0, rate=10.0, sigma=0.1, nlos=0.0, drop=0.0,
               seed=0, storage='mcap', raw_protocol=None, start_ns=None):
    """
    Write a simulated working cycle as a bag (:func:`write_cycles`).

    Returns
    -------
    dict
        Messages written per topic.

    """
    model = config.model()
    rng = np.random.default_rng(seed)
    trajectory = working_cycle(model, duration, rate, rng=np.random.default_rng(seed))
    noise = RangeNoise(sigma=sigma, nlos_fraction=nlos, nlos_gamma=2.0, dropout=drop)
    start_ns = time.time_ns() if start_ns is None else int(start_ns)
    cycles = ((start_ns + int(round(seconds * 1e9)), noise.apply(model.ranges(joints), rng)[0],
               joints, None) for seconds, joints in zip(trajectory.times, trajectory.joints))
    return write_cycles(path, config, cycles, storage, raw_protocol)


def write_cycles(path, config, cycles, storage='mcap', raw_protocol=None, anchor_rounds=None):
    """
    Write simulated cycles: ``/uwb/ranges`` and ``/arm_posture/ground_truth``, same stamp.

    Parameters
    ----------
    path : path
        The bag to create (a directory).
    config : epp_ros.app.config.PumpConfig
        The pump: frame id and link names of the messages.
    cycles : iterable of (int, ndarray, ndarray, ndarray or None)
        ``(stamp_ns, ranges (p, m) metres, true joints (p, 3) metres, ages)``; ``ages``
        (p, m) seconds before the stamp each range was measured, or None (at the stamp).
    storage : str
        ``'mcap'`` or ``'sqlite3'``.
    raw_protocol : str, optional
        Also write the devices' lines of that format on ``/uwb/raw``.
    anchor_rounds : callable, optional
        ``cycle index -> list of (m, m) ndarray``: rounds of anchor-anchor ranges (metres,
        NaN where not measured) written on ``/uwb/anchor_ranges`` at the cycle's stamp,
        before its ranges (on ``/uwb/raw`` too, as far as the format carries them).

    Returns
    -------
    dict
        Messages written per topic.

    """
    model = config.model()
    counts = {}
    with BagWriter(path, storage) as bag:
        for cycle, (stamp, ranges, joints, ages) in enumerate(cycles):
            messages = _anchor_messages(config, stamp, cycle, anchor_rounds, raw_protocol)
            messages += [(RANGES, _ranges_message(stamp, config.frame_id, config.link_names,
                                                  ranges, ages, number=cycle + 1)),
                         (TRUTH, _posture_message(stamp, config.frame_id,
                                                  model.pivot_of(joints), joints))]
            if raw_protocol:
                messages += [(RAW, TYPESTORE.types[TYPES[RAW]](data=line))
                             for _, line in cycle_lines(config, ranges, raw_protocol, cycle)]
            for topic, message in messages:
                bag.write(topic, stamp, _serialize(message))
                counts[topic] = counts.get(topic, 0) + 1
    return counts


def _anchor_messages(config, stamp, cycle, anchor_rounds, raw_protocol):
    """Return the (topic, message) pairs of a cycle's anchor-anchor rounds (none without)."""
    messages = []
    for ranges in ([] if anchor_rounds is None else anchor_rounds(cycle)):
        messages.append((ANCHOR_RANGES, _anchor_ranges_message(stamp, config, ranges)))
        if raw_protocol:
            messages += [(RAW, TYPESTORE.types[TYPES[RAW]](data=line))
                         for _, line in anchor_lines(config, ranges, raw_protocol, cycle)]
    return messages


def write_frames(path, config, frames, storage='mcap', ages=None):
    """
    Write range frames as ``/uwb/ranges``, exactly as uwb_driver publishes them.

    Parameters
    ----------
    path : path
        The bag to create (a directory).
    config : epp_ros.app.config.PumpConfig
        The pump: frame id and link names of the messages.
    frames : iterable of (int, ndarray)
        ``(stamp_ns, ranges)`` with ranges (p, m) in metres, NaN where missing.
    storage : str
        ``'mcap'`` or ``'sqlite3'``.
    ages : iterable of ndarray, shape (p, m), optional
        One per frame, in order: seconds before its stamp each range was measured
        (``effort``, ``contract.range_ages``). Without them ``effort`` is empty: every
        range at its frame's stamp.

    Returns
    -------
    int
        Messages written.

    Raises
    ------
    ValueError
        When ``ages`` is given and not one per frame.

    """
    count = 0
    per_frame = ((*frame, None) for frame in frames) if ages is None \
        else ((*frame, age) for frame, age in zip(frames, ages, strict=True))
    with BagWriter(path, storage) as bag:
        for stamp_ns, ranges, frame_ages in per_frame:
            count += 1
            message = _ranges_message(stamp_ns, config.frame_id, config.link_names, ranges,
                                      frame_ages, number=count)
            bag.write(RANGES, stamp_ns, _serialize(message))
    return count


class _Bag:
    """A bag opened for reading, with one-line errors."""

    def __init__(self, path):
        self.path = Path(path)
        if not self.path.exists():
            raise BagError(f'{path}: no such bag')
        if self.path.is_dir() and not (self.path / 'metadata.yaml').exists() and \
                any(self.path.glob('*.mcap')):
            raise BagError(f'{path}: no metadata.yaml: its recorder never closed it (killed?); '
                           f'`epp_bag reindex {path}` recovers it up to its last whole chunk')
        try:
            self.reader = Reader(self.path)
            self.reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on bad files
            raise BagError(f'{path}: not a readable rosbag2 bag ({exc})') from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.reader.close()

    def connections(self, topic, msgtype):
        found = [c for c in self.reader.connections if c.topic == topic]
        if not found:
            raise BagError(f'{self.path}: no {topic} topic (topics: '
                           f'{sorted({c.topic for c in self.reader.connections})})')
        wrong = [c.msgtype for c in found if c.msgtype != msgtype]
        if wrong:
            raise BagError(f'{self.path}: {topic} holds {wrong[0]}, expected {msgtype}')
        return found

    def messages(self, topic, msgtype):
        """Yield (t_ns, message) of one topic, deserialized; BagError on a broken message."""
        connections = self.connections(topic, msgtype)
        try:
            for connection, t_ns, raw in self.reader.messages(connections=connections):
                yield t_ns, TYPESTORE.deserialize_cdr(raw, connection.msgtype)
        except BagError:
            raise
        except Exception as exc:  # noqa: BLE001 - truncated files, other definitions
            raise BagError(f'{self.path}: cannot read {topic}: {exc}') from None


def _stamp_ns(message):
    return message.header.stamp.sec * 10 ** 9 + message.header.stamp.nanosec


def info(path):
    """Storage, duration and topics of a bag, as ``ros2 bag info`` shows them."""
    with _Bag(path) as bag:
        reader = bag.reader
        return {'path': str(path), 'storage': _storage_of(bag),
                'duration_s': reader.duration / 1e9 if reader.message_count else 0.0,
                'start_ns': reader.start_time if reader.message_count else 0,
                'messages': reader.message_count,
                'topics': [{'topic': c.topic, 'type': c.msgtype, 'count': c.msgcount}
                           for c in reader.connections]}


def evaluate(path, config, method='cepp', out=None, salvage=False, **options):
    """
    Run an estimator over a bag's ``/uwb/ranges``; score it against the truth if any.

    Parameters
    ----------
    path : path
        The bag to read.
    config : epp_ros.app.config.PumpConfig
        The pump the bag was recorded on.
    method : str
        A name in :data:`epp_ros.core.METHODS`.
    out : path, optional
        A copy of the bag with the estimated ``/arm_posture`` added; must not exist.
    salvage : bool
        Evaluate what can be read of a damaged bag (``damage`` says what was skipped)
        instead of refusing it.
    **options
        Passed to :class:`PostureEstimator`.

    Returns
    -------
    dict
        ``frames``, ``solved`` (published by the node's policy), ``rejected`` (frames not
        published, by reason), ``ignored`` (frames the stamp rules skip, by reason:
        ``core.frame_policy``), ``published_stamps_ns``, ``rmse_m`` (NaN without truth),
        ``joint_rmse_m`` (p,), ``max_arm_length_error_m``, ``ms_per_frame``, ``method``, and
        the per-frame series ``stamps_ns``, ``frame_rmse_m`` for plotting.

    """
    if out is not None and Path(out).exists():
        raise BagError(f'{out} exists already')
    damage = check(path)
    if not damage.intact and not salvage:
        raise BagError(f'{path}: damaged: {damage.describe()} (--salvage uses what could '
                       'be read)')
    model = config.model()
    estimator = PostureEstimator(model, method, moving_anchors=config.moving_anchor_indices,
                                 **config.with_link_biases(options))
    run = _Evaluation(model, estimator, config)
    with _Bag(path) as bag:
        bag.connections(RANGES, TYPES[RANGES])            # there, and of the right type
        if any(c.topic == TRUTH for c in bag.reader.connections):
            bag.connections(TRUTH, TYPES[TRUTH])
        writer = BagWriter(out, _storage_of(bag)) if out is not None else None
        with writer or contextlib.nullcontext():
            for connection, t_ns, raw, message in _decoded(bag, salvage):
                _evaluate_message(run, writer, connection, t_ns, raw, message)
    return dict(run.report(), method=method,
                damage=None if damage.intact else damage.describe())


def _evaluate_message(run, writer, connection, t_ns, raw, message):
    """Take one message of the bag: copy it (and a posture it gives) to ``writer``, if any."""
    if writer is not None:
        writer.write(connection.topic, t_ns, bytes(raw), connection.msgtype,
                     _offered_qos(connection))
    if connection.topic == RANGES:
        posture = run.frame(message)
        if posture is not None and writer is not None:
            writer.write(POSTURE, posture[0], _serialize(posture[1]))
    elif connection.topic == TRUTH:
        run.truth(message)


class _Evaluation:
    """
    One pass of an estimator over a bag's frames, scored as they come: memory stays flat.

    Frames and truths are matched by stamp within ``window_ns`` of the newest (a recorder
    may store either first); per-frame series are kept as 8-byte arrays.
    """

    def __init__(self, model, estimator, config, window_ns=10 ** 10):
        self.model, self.config = model, config
        self.pipeline = RangePipeline(config, estimator)    # the node's steps and counts
        self.window_ns = window_ns
        self.pending = {'truth': {}, 'estimate': {}}
        self.published = array('q')
        self.scored_stamps, self.scored_rmse = array('q'), array('d')
        self.squared = np.zeros(model.n_sections)
        self.max_length_error = float('nan')
        self.elapsed = 0.0

    def frame(self, message):
        """Solve one ``/uwb/ranges`` message; return (stamp_ns, PoseArray) if published."""
        stamp = _stamp_ns(message)
        start = time.perf_counter()
        step = self.pipeline.step(stamp * 1e-9, list(message.name), message.position,
                                  message.effort)
        self.elapsed += time.perf_counter() - start
        if step.joints is None:
            return None
        self.published.append(stamp)
        error = float(np.max(step.diagnostics.arm_length_error))
        self.max_length_error = np.fmax(self.max_length_error, error)
        self._match('estimate', stamp, step.joints)
        return stamp, _posture_message(stamp, self.config.frame_id,
                                       self.model.pivot_of(step.joints), step.joints)

    def truth(self, message):
        """Take one ``/arm_posture/ground_truth`` message."""
        self._match('truth', _stamp_ns(message), contract.joints_of(message))

    def _match(self, kind, stamp, joints):
        other = 'truth' if kind == 'estimate' else 'estimate'
        partner = self.pending[other].pop(stamp, None)
        if partner is None:
            self.pending[kind][stamp] = joints
            self._forget_before(stamp - self.window_ns)
            return
        estimate, truth = (joints, partner) if kind == 'estimate' else (partner, joints)
        self.scored_stamps.append(stamp)
        self.scored_rmse.append(float(frame_rmse(estimate, truth)))
        self.squared += joint_errors(estimate, truth) ** 2

    def _forget_before(self, oldest):
        for waiting in self.pending.values():
            for stamp in [s for s in waiting if s < oldest]:
                del waiting[stamp]

    def report(self):
        """Return the evaluation as :func:`evaluate` does."""
        scored = len(self.scored_rmse)
        counts = self.pipeline.counts
        return {'frames': counts['received'], 'solved': counts['published'],
                'rejected': self.pipeline.rejected(), 'ignored': self.pipeline.ignored(),
                'published_stamps_ns': list(self.published),
                'rmse_m': pooled_rmse(np.asarray(self.scored_rmse)),
                'joint_rmse_m': np.sqrt(self.squared / scored).tolist() if scored else [],
                'max_arm_length_error_m': float(self.max_length_error),
                'ms_per_frame': 1e3 * self.elapsed / max(counts['received'], 1),
                'stamps_ns': list(self.scored_stamps),
                'frame_rmse_m': list(self.scored_rmse)}


def _decoded(bag, salvage):
    """Yield (connection, t_ns, raw, message) of every decodable message, in time order."""
    try:
        for connection, t_ns, raw in bag.reader.messages():
            try:
                message = TYPESTORE.deserialize_cdr(raw, connection.msgtype)
            except Exception:  # noqa: BLE001 - corrupt CDR: skipped (checked beforehand)
                continue
            yield connection, t_ns, raw, message
    except Exception as exc:  # noqa: BLE001 - damaged storage (checked beforehand)
        if not salvage:
            raise BagError(f'{bag.path}: cannot read: {exc}') from None


def _offered_qos(connection):
    profiles = getattr(connection.ext, 'offered_qos_profiles', None)
    return profiles[0] if profiles else None


def _storage_of(bag):
    files = [p.suffix for p in bag.path.iterdir()] if bag.path.is_dir() else []
    return 'sqlite3' if '.db3' in files else 'mcap'


@dataclass
class Damage:
    """
    What of a bag could not be read: its metadata's counts against what was.

    Attributes
    ----------
    expected : dict
        Messages per topic, as the bag's metadata counts them.
    read : dict
        Messages per topic read and decoded.
    undecodable : dict
        Messages per topic read but not decodable (corrupt CDR); skipped.
    error : str or None
        Why reading stopped early, if it did.

    """

    expected: dict
    read: dict = field(default_factory=dict)
    undecodable: dict = field(default_factory=dict)
    error: str = None

    @property
    def intact(self):
        """Whether every message the metadata counts was read and decoded."""
        return self.error is None and all(self.read.get(topic, 0) == count
                                          for topic, count in self.expected.items())

    def describe(self):
        """One line: what was read of what, and what was skipped and why."""
        total = sum(self.expected.values())
        topics = ', '.join(f'{topic} {self.read.get(topic, 0)} of {count}'
                           for topic, count in self.expected.items())
        line = f'read {sum(self.read.values())} of {total} messages ({topics})'
        broken = sum(self.undecodable.values())
        if broken:
            line += f'; {broken} undecodable, skipped'
        missing = total - sum(self.read.values()) - broken
        if missing > 0:
            line += f'; {missing} lost in damaged storage'
        if self.error:
            line += f'; reading stopped: {self.error}'
        return line


def read_all(path, salvage=False, topics=None):
    """
    Every intact message of a bag as (topic, msgtype, t_ns, raw bytes, qos or None).

    Each message is decoded to be sure it is whole, and the counts compared with the
    bag's metadata: rosbags reads past damaged storage without a word.

    Parameters
    ----------
    path : path
        The bag.
    salvage : bool
        Return what could be read of a damaged bag instead of refusing it.
    topics : collection of str, optional
        Only these topics (all by default).

    Returns
    -------
    messages : list
    damage : Damage

    Raises
    ------
    BagError
        On a damaged bag, saying what was read and skipped, unless ``salvage``.

    """
    with _Bag(path) as bag:
        connections = [c for c in bag.reader.connections
                       if topics is None or c.topic in topics]
        damage = Damage({c.topic: c.msgcount for c in connections})
        messages = []
        try:
            for connection, t_ns, raw in bag.reader.messages(connections=connections):
                if not _decodes(raw, connection.msgtype):
                    _count(damage.undecodable, connection.topic)
                    continue
                _count(damage.read, connection.topic)
                messages.append((connection.topic, connection.msgtype, t_ns, bytes(raw),
                                 _offered_qos(connection)))
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on bad files
            damage.error = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
        if not damage.intact and not salvage:
            raise BagError(f'{path}: damaged: {damage.describe()} (--salvage uses what could '
                           'be read)')
        return messages, damage


def read_anchor_ranges(path, config, salvage=False, malformed=None):
    """
    Read a bag's ``/uwb/anchor_ranges``: every round of anchor-anchor ranges.

    Parameters
    ----------
    path : path
        The bag.
    config : epp_ros.app.config.PumpConfig
        The pump: the anchors' names.
    salvage : bool
        Use what can be read of a damaged topic instead of refusing it.
    malformed : list, optional
        Given, a malformed message is skipped (its round all NaN) and why is appended
        here; without, it is a :class:`BagError`.

    Returns
    -------
    ndarray, shape (K, m, m)
        One round per message, in time order: row i anchor i's ranges, metres, NaN where
        not measured. K = 0 when the bag has no ``/uwb/anchor_ranges`` (older bags).

    Raises
    ------
    BagError
        On a bag that cannot be read, another message type on the topic, a malformed
        message (unless ``malformed`` collects them), or labels of which none names two
        configured anchors.

    """
    m = len(config.anchor_names)
    topics = {entry['topic']: entry['type'] for entry in info(path)['topics']}
    if ANCHOR_RANGES not in topics:
        return np.full((0, m, m), np.nan)
    if topics[ANCHOR_RANGES] != TYPES[ANCHOR_RANGES]:
        raise BagError(f'{path}: {ANCHOR_RANGES} holds {topics[ANCHOR_RANGES]}, expected '
                       f'{TYPES[ANCHOR_RANGES]}')
    messages, _ = read_all(path, salvage=salvage, topics=[ANCHOR_RANGES])
    rounds, unknown = np.full((len(messages), m, m), np.nan), 0
    for index, (_, msgtype, _, raw, _) in enumerate(messages):
        message = TYPESTORE.deserialize_cdr(raw, msgtype)
        try:
            rounds[index], missed = contract.anchor_range_matrix(
                config.anchor_names, list(message.name), message.position)
        except ValueError as exc:
            if malformed is None:
                raise BagError(f'{path}: a {ANCHOR_RANGES} message is malformed: {exc}') \
                    from None
            malformed.append(str(exc))
            continue
        unknown += missed
    if unknown and not np.isfinite(rounds).any():
        raise BagError(f'{path}: no {ANCHOR_RANGES} label names two anchors of the config '
                       '(recorded with another pump.yaml? see --config)')
    return rounds


def check(path):
    """Return the :class:`Damage` of a bag (read and decode every message, keep none)."""
    with _Bag(path) as bag:
        damage = Damage({c.topic: c.msgcount for c in bag.reader.connections})
        try:
            for connection, _, raw in bag.reader.messages():
                counts = damage.read if _decodes(raw, connection.msgtype) \
                    else damage.undecodable
                _count(counts, connection.topic)
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on bad files
            damage.error = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
        return damage


def _decodes(raw, msgtype):
    try:
        TYPESTORE.deserialize_cdr(raw, msgtype)
    except Exception:  # noqa: BLE001 - any decoding failure means a corrupt message
        return False
    return True


def _count(counts, key):
    counts[key] = counts.get(key, 0) + 1


def write_raw(path, messages, storage='mcap'):
    """Write (topic, msgtype, t_ns, raw bytes, qos or None) messages as a bag."""
    with BagWriter(path, storage) as bag:
        for topic, msgtype, t_ns, raw, qos in messages:
            bag.write(topic, t_ns, raw, msgtype, qos)


#: MCAP's magic, at both ends of a file.
_MCAP_MAGIC = b'\x89MCAP0\r\n'
#: Its record opcodes (header 0x01 ... data end 0x0F); anything else is not a record.
_MCAP_OPCODES = range(0x01, 0x10)


def _whole_records_end(storage):
    """Return the offset after the last whole MCAP record of ``storage`` (a killed file)."""
    import struct
    with open(storage, 'rb') as stream:
        if stream.read(len(_MCAP_MAGIC)) != _MCAP_MAGIC:
            raise BagError(f'{storage}: not an MCAP file')
        size = storage.stat().st_size
        end = stream.tell()
        while end + 9 <= size:
            opcode, length = struct.unpack('<BQ', stream.read(9))
            if opcode not in _MCAP_OPCODES or end + 9 + length > size:
                break                           # cut off mid-record, or never written
            end = stream.seek(length, 1)
        return end


def reindex(path):
    """
    Make a bag whose recorder was killed readable, up to its last whole chunk.

    rosbag2 writes ``metadata.yaml``, and MCAP its summary and footer, when a recording is
    closed: after a SIGKILL or a power cut a bag has neither, and no reader opens it. The
    MCAP file holds every chunk the recorder had written (``BagWriter`` writes one per MiB);
    this keeps its whole records, ends them with a footer and writes the bag again,
    metadata and all, in place (as ``ros2 bag reindex``).

    Returns
    -------
    counts : dict
        Messages recovered per topic.
    lost_bytes : int
        Bytes of the unfinished record at the end, dropped.
    stopped : str or None
        Why reading stopped before the last whole record (a damaged chunk), or None.

    Raises
    ------
    BagError
        On a bag that has its metadata, is not a folder of one MCAP file (sqlite3 storage
        keeps nothing its writer had not committed on close), or is unreadable even so.

    """
    import tempfile
    path = Path(path)
    if not path.is_dir():
        raise BagError(f'{path}: no such bag folder')
    if (path / 'metadata.yaml').exists():
        raise BagError(f'{path}: has its metadata.yaml: nothing to reindex')
    storages = sorted(path.glob('*.mcap'))
    if len(storages) != 1:
        raise BagError(f'{path}: {len(storages)} MCAP files, need one (a sqlite3 recording '
                       'keeps nothing its recorder did not close)')
    storage = storages[0]
    size, end = storage.stat().st_size, _whole_records_end(storage)
    with tempfile.TemporaryDirectory(prefix=f'.{path.name}.', dir=path.parent) as work:
        work = Path(work)
        repaired = work / 'whole.mcap'
        with open(storage, 'rb') as source, open(repaired, 'wb') as target:
            _copy_bytes(source, target, end)
            # A footer without a summary: readers scan the records.
            target.write(b'\x02' + (20).to_bytes(8, 'little') + bytes(20) + _MCAP_MAGIC)
        counts, stopped = _copy_readable(repaired, work / path.name)
        for written in (work / path.name).iterdir():      # the storage first, metadata last
            if written.name != 'metadata.yaml':
                os.replace(written, path / written.name)
        if storage.name != f'{path.name}.mcap':
            storage.unlink()
        os.replace(work / path.name / 'metadata.yaml', path / 'metadata.yaml')
    return counts, size - end, stopped


def _copy_bytes(source, target, count, block=1 << 20):
    """Copy the first ``count`` bytes of ``source`` to ``target``, a block at a time."""
    while count > 0:
        data = source.read(min(block, count))
        if not data:
            break
        target.write(data)
        count -= len(data)


def _copy_readable(storage, out):
    """
    Write every message a reader gets from the MCAP file ``storage`` as the bag ``out``.

    Returns the messages copied per topic, and why reading stopped early (None: it did not).
    """
    counts = {}
    try:
        reader = Reader(storage)
        reader.open()
    except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds on bad files
        raise BagError(f'{storage}: unreadable even up to its last whole record ({exc})') \
            from None
    stopped = None
    try:
        with BagWriter(out) as bag:
            messages = reader.messages()
            while True:
                try:
                    connection, t_ns, raw = next(messages)
                except StopIteration:
                    break
                except Exception as exc:  # noqa: BLE001 - a broken chunk: keep what came before
                    stopped = str(exc).splitlines()[0][:200] if str(exc) else type(exc).__name__
                    break
                bag.write(connection.topic, t_ns, raw, connection.msgtype,
                          _offered_qos(connection))
                _count(counts, connection.topic)
    finally:
        reader.close()
    return counts, stopped
