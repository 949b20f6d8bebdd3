"""Refinement of a known-pose model (issue 29): the keyframe poses and points bundle-adjusted
(refine_model, C++/Ceres), outliers filtered, points re-triangulated at the refined poses; and
the seeded drift that the measurements add to exact poses."""
