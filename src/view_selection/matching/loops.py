"""Pairs across a revisit that the poses do not show (issue 34, "a refined model at every length").

A SLAM system's or an odometry's drift grows with the distance travelled: when the camera comes
back to a place after a long walk, the poses put it beside where it was, not there, and the
node's selection (which reasons from the poses) pairs it with its recent neighbours only. The
drift is then unobservable: measured on a 5-minute walk with the odometry stand-in's poses (1,033
keyframes, 347 mm ATE), no verified pair spanned more than 500 keyframes, and a refinement to
convergence kept 273 mm; with these pairs matched it reached 2.9 mm.

A keyframe the node links to an earlier one it was recognised from the images to revisit
(`revisit_of`, the node's ~revisit_registration) is proposed with it first, whatever the poses
say: the node then makes no keyframes where the walk revisits, so that the poses' search below
finds few to pair (measured on test_loop_pairs' walk: 2 loop pairs, 17.5 mm refined, against 6
and 5.3 mm with the revisits' keyframes).

For each other new keyframe (in the order they were accepted), the earlier keyframes at least
`min_gap` keyframes back, whose centre lies within `radius + drift_ratio x` the path travelled
between the two, and whose optical axes differ by at most `max_angle_deg`, are candidates; the
`per_keyframe` nearest whose neighbourhoods (`neighbourhood` keyframes either side) are not
already joined by a wanted pair are proposed, for one keyframe in `spacing` at most (a keyframe
`spacing` after the last one given a pair). Each keyframe is looked at once, when it first comes.

On that walk, one loop pair every 5 keyframes (182 pairs, 4 s of COLMAP's matching) brought a
5 s refinement to 15.6 mm (3.2 mm to convergence), one for every keyframe (871 pairs, 34 s) to
22.5 mm (4.1 mm), one every 10 (92) to 52.8 mm (4.1 mm): a few pairs at each revisit close the
loop, and a smaller problem converges further within the budget. The pairs go to the matching like the node's: guided by the poses where the drift is
small, COLMAP's matcher where it is not, and only what verifies reaches the model and the
refinement.
"""
import math

import numpy as np

from .. import geometry
from ..keyframes import pair_of


class LoopOptions:
    def __init__(self, min_gap=60, radius=0.3, drift_ratio=0.02, max_angle_deg=30.0, per_keyframe=1,
                 neighbourhood=3, spacing=5):
        self.min_gap, self.radius, self.drift_ratio = int(min_gap), float(radius), float(drift_ratio)
        self.spacing = max(1, int(spacing))
        self.max_angle_deg, self.per_keyframe = float(max_angle_deg), int(per_keyframe)
        self.neighbourhood = int(neighbourhood)
        if self.min_gap < 1 or self.per_keyframe < 0 or self.neighbourhood < 0:
            raise ValueError("loop candidates: min_gap >= 1, per_keyframe >= 0 and neighbourhood >= 0")
        if not (self.radius >= 0 and self.drift_ratio >= 0 and 0 < self.max_angle_deg <= 180):
            raise ValueError("loop candidates: radius and drift_ratio >= 0, max_angle_deg in (0, 180]")


class LoopCandidates:
    """The pairs across revisits proposed so far (`pairs`, names sorted within), grown by
    `update()` with the session's keyframes and the pairs already wanted."""

    def __init__(self, options=None):
        self.options = options or LoopOptions()
        self.pairs = set()
        self._names = []       # in the order they were accepted (keyframe id)
        self._index = {}       # name -> position in _names
        self._centres = np.zeros((0, 3))
        self._axes = np.zeros((0, 3))
        self._path = np.zeros(0)  # path travelled up to each keyframe, along the keyframes
        self._last_proposed = -10 ** 9  # position of the last keyframe given a pair
        self._index_by_id = {}  # keyframe id -> position in _names (for revisit_of)
        self.registered = set()  # of `pairs`, those the node's revisit_of links gave

    def update(self, keyframes, wanted):
        """Looks at the keyframes not seen yet (by id) and returns the pairs proposed now.
        `wanted`: the pairs (names, sorted within) already wanted, which a proposal must not
        duplicate (looked up, never gone through: a batch's work is the new keyframes')."""
        new = sorted((k for k in keyframes if k.name not in self._index), key=lambda k: k.id)
        if not new:
            return []
        o = self.options
        start = len(self._names)
        for k in new:
            self._index[k.name] = self._index_by_id[k.id] = len(self._names)
            self._names.append(k.name)
        self._centres = np.vstack([self._centres, np.array([k.position for k in new], float)])
        axes = [geometry.rotation_of(k.orientation)[:, 2] for k in new]  # the optical axis in the world
        self._axes = np.vstack([self._axes, np.array(axes, float)])
        steps = np.linalg.norm(np.diff(self._centres[max(0, start - 1):], axis=0), axis=1)
        if start == 0:
            steps = np.concatenate([[0.0], steps])
        self._path = np.concatenate([self._path, (self._path[-1] if start else 0.0) + np.cumsum(steps)])
        proposed = []
        cos_max = math.cos(math.radians(o.max_angle_deg))
        for j, k in zip(range(start, len(self._names)), new):
            earlier = self._index_by_id.get(k.revisit_of)
            if earlier is not None and o.per_keyframe > 0:
                # The node recognised from the images that the walk revisits that keyframe here
                # (its ~revisit_registration): proposed whatever the poses say, spacing or not.
                if not self._already_joined(earlier, j, wanted):
                    pair = pair_of(self._names[earlier], self._names[j])
                    proposed.append(pair)
                    self.pairs.add(pair)
                    self.registered.add(pair)
                    self._last_proposed = j
                continue
            last = j - o.min_gap
            if last < 0 or o.per_keyframe == 0 or j - self._last_proposed < o.spacing:
                continue
            distance = np.linalg.norm(self._centres[:last + 1] - self._centres[j], axis=1)
            reach = o.radius + o.drift_ratio * (self._path[j] - self._path[:last + 1])
            near = np.nonzero((distance <= reach) & (self._axes[:last + 1] @ self._axes[j] >= cos_max))[0]
            taken = 0
            for i in near[np.argsort(distance[near])]:
                if taken >= o.per_keyframe:
                    break
                if self._already_joined(int(i), j, wanted):
                    continue
                pair = pair_of(self._names[int(i)], self._names[j])
                proposed.append(pair)
                self.pairs.add(pair)
                self._last_proposed = j
                taken += 1
        return proposed

    def _already_joined(self, i, j, wanted):
        """Whether a wanted or proposed pair joins keyframe i's neighbourhood with j's."""
        w, n = self.options.neighbourhood, len(self._names)
        for a in range(max(0, i - w), min(n, i + w + 1)):
            for b in range(max(0, j - w), min(n, j + w + 1)):
                if a != b:
                    pair = pair_of(self._names[a], self._names[b])
                    if pair in wanted or pair in self.pairs:
                        return True
        return False
