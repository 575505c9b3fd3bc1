"""epp_demo: the posture estimator live on the built-in simulated pump.

Until the ROS nodes land this runs in one process: a truck-mounted pump follows a working
cycle, its UWB ranges get noise and dropouts, and the estimator solves every frame in real
time. The terminal shows each joint's estimate and error against the truth, the running
RMSE, the frame rate and the solve time.
"""
import argparse
import json
import sys
import time

import numpy as np

from epp_ros.core import METHODS, PostureEstimator
from epp_ros.core.metrics import frame_rmse, joint_errors, pooled_rmse
from epp_ros.core.simulate import RangeNoise, truck_pump, working_cycle


def parse_args(argv):
    parser = argparse.ArgumentParser(prog='epp_demo', description=__doc__.splitlines()[0])
    parser.add_argument('--method', choices=sorted(METHODS), default='cepp')
    parser.add_argument('--duration', type=float, default=None,
                        help='seconds to run (default: until Ctrl-C)')
    parser.add_argument('--rate', type=float, default=10.0, help='frames per second')
    parser.add_argument('--sigma', type=float, default=0.1, help='range noise, metres')
    parser.add_argument('--drop', type=float, default=0.05, help='link dropout probability')
    parser.add_argument('--nlos', type=float, default=0.0, help='fraction of NLOS links')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--fast', action='store_true', help='do not wait for real time')
    parser.add_argument('--json', action='store_true',
                        help='print a JSON summary as the last stdout line')
    args = parser.parse_args(argv)
    if args.rate <= 0 or (args.duration is not None and args.duration <= 0):
        parser.error('--rate and --duration must be positive')
    return args


def render(estimate, truth, stats, args):
    """The live view as text."""
    errors = joint_errors(estimate, truth)
    lines = [f'epp_demo  method={args.method}  sigma={args.sigma} m  drop={args.drop}  '
             f'nlos={args.nlos}   (Ctrl-C to stop)', '',
             '  joint      x [m]      y [m]      z [m]    error [m]']
    for k, (position, error) in enumerate(zip(estimate, errors), start=1):
        lines.append(f'  {k:5d} {position[0]:10.2f} {position[1]:10.2f} {position[2]:10.2f}'
                     f' {error:12.3f}')
    solve = 1e3 * np.array(stats['solve_times'])
    lines += ['', f'  frames {stats["frames"]}   rate {stats["rate"]:.1f} Hz   '
              f'running RMSE {pooled_rmse(stats["rmses"]):.3f} m   '
              f'solve p50 {np.median(solve):.1f} ms  p99 {np.percentile(solve, 99):.1f} ms   '
              f'status {stats["status"]}   not solved {stats["dropped"]}']
    return '\n'.join(lines)


def summary(stats, args):
    solve = 1e3 * np.array(stats['solve_times']) if stats['solve_times'] else np.zeros(1)
    return {'frames': stats['frames'], 'rmse_m': pooled_rmse(stats['rmses']),
            'max_joint_error_m': stats['max_error'],
            'latency_p50_ms': float(np.median(solve)),
            'latency_p99_ms': float(np.percentile(solve, 99)),
            'dropped_frames': stats['dropped'], 'method': args.method}


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    view = sys.stderr if args.json else sys.stdout
    live = view.isatty()
    rng = np.random.default_rng(args.seed)
    model = truck_pump()
    cycle_length = 120.0
    trajectory = working_cycle(model, cycle_length, args.rate, rng=rng)
    noise = RangeNoise(sigma=args.sigma, dropout=args.drop, nlos_fraction=args.nlos,
                       nlos_gamma=2.0)
    estimator = PostureEstimator(model, args.method)
    stats = {'frames': 0, 'rmses': [], 'solve_times': [], 'dropped': 0, 'max_error': 0.0,
             'rate': 0.0, 'status': '-'}
    total = None if args.duration is None else int(round(args.duration * args.rate))
    start = last_render = time.monotonic()
    try:
        while total is None or stats['frames'] < total:
            index = stats['frames'] % len(trajectory.times)
            truth = trajectory.joints[index]
            estimate = estimator.update(noise.apply(model.ranges(truth), rng)[0])
            diagnostics = estimator.last_diagnostics
            stats['frames'] += 1
            stats['status'] = diagnostics['status']
            stats['solve_times'].append(diagnostics['solve_time'])
            if diagnostics['valid']:
                stats['rmses'].append(float(frame_rmse(estimate, truth)))
                stats['max_error'] = max(stats['max_error'],
                                         float(joint_errors(estimate, truth).max()))
            else:
                stats['dropped'] += 1
            now = time.monotonic()
            stats['rate'] = stats['frames'] / max(now - start, 1e-9)
            if now - last_render >= (0.2 if live else 1.0):
                last_render = now
                text = render(estimate, truth, stats, args)
                if live:
                    view.write('\033[H\033[J' + text + '\n')
                else:
                    view.write(text.splitlines()[-1].strip() + '\n')
                view.flush()
            if not args.fast:
                time.sleep(max(0.0, start + stats['frames'] / args.rate - time.monotonic()))
    except KeyboardInterrupt:
        pass
    result = summary(stats, args)
    view.write(f'\nepp_demo: {result["frames"]} frames, RMSE {result["rmse_m"]:.3f} m, '
               f'max joint error {result["max_joint_error_m"]:.3f} m, solve p50 '
               f'{result["latency_p50_ms"]:.1f} ms / p99 {result["latency_p99_ms"]:.1f} ms, '
               f'{result["dropped_frames"]} frames not solved\n')
    if args.json:
        print(json.dumps(result))
    return 0


if __name__ == '__main__':
    sys.exit(main())
