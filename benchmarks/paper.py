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
``dev.py bench paper``: the seed paper's experiments, our figures next to its published ones.

1. RMSE against the noise, multiplicative eta (the paper's figure) and additive sigma, with
   the Cramér–Rao bound of the chain model; cold start every run. Per point the mean of the
   per-run RMSE (what the paper plots) and its RMS (what the bound bounds).
2. Table 1: absolute arm-length error per section and CPU time (eta = 0.1, from part 1).
3. Table 3: NLOS ranges (sigma = 0.2 m, exponential excess of mean 2 m on 20 % of links)
   on the truck pump, random postures, against the bound of the LOS links alone; the
   paper's figures are means of the per-run RMSE.
4. The authors' xie3dim geometry at sigma = 1 m, next to their published figures (the
   mean of the per-trial RMSE over 3,000 trials, and its RMS from their code): EPP1 with
   and without Toh's post-processing (EMBED refines EPP1 and CEPP by gradient descent on
   the unsquared stress after the embedding), EPP2, the paper's CEPP from our cold start
   (its plane from the frame) and as the authors ran it (its plane from the true posture,
   with and without Toh's post-processing), the chain, SR-LS and SDP.
5. Tracking: a working cycle at 10 Hz, warm-started.
6. The chain estimator's targets: RMSE / CRLB on 4-6 sections, 4-6 anchors, 15 % missing.

The paper's geometry is not printed; its p = 5, 9/7/7/9/9 m manipulator is the authors'
xie3dim anchors and posture (``simulate.XIE3DIM``) with those exact lengths. The paper
gives neither the eta of Table 1, nor the NLOS fraction, nor TPSM's inclinometer noise;
ours are stated in each table. The experiments are :mod:`benchmarks.experiments`',
the formatting :mod:`benchmarks.reports`'.
"""
from dataclasses import replace

from benchmarks.experiments import paper_experiments
from benchmarks.reports import write_paper


def run(out, runs, seed, methods=None, tracking_seconds=60.0, target_runs=None):
    """
    Run every part; write paper.md, paper.json and the PNG plots into ``out``.

    Parameters
    ----------
    out : str or Path
        Folder, created if need be.
    runs, seed, methods, tracking_seconds, target_runs
        See :func:`~benchmarks.experiments.paper_experiments`.

    Returns
    -------
    PaperReport
        With ``out`` set.

    """
    report = replace(paper_experiments(runs, seed, methods, tracking_seconds, target_runs),
                     out=str(out))
    write_paper(report, out)
    return report
