"""Scans for tests: the lidar conventions every policy must handle, and scans painted by sector."""

import math

import numpy as np

from safenav import PRESET_NAMES, LaserScan, LidarSpec, Pose2D, preset

DEG = math.pi / 180.0
INF, NAN = math.inf, math.nan

# ------------------------------------------------------------------ lidar conventions

LIDARS = {
    # The three tutorial robots: mounted backwards over -pi..pi; 0..2pi; 180 degrees with beam 0 on the right.
    **{name: preset(name).lidar for name in PRESET_NAMES},
    # A Hokuyo URG-04LX-like 240-degree scan, 0.02-5.6 m.
    "hokuyo_240": LidarSpec(n_beams=683, angle_min=-120 * DEG, angle_max=120 * DEG, range_min=0.02, range_max=5.6),
    # A 360-degree lidar mounted sideways and off-centre: its beam 0 looks left.
    "rotated_mount": LidarSpec(n_beams=400, angle_min=0.0, angle_max=2 * math.pi * 399 / 400, range_min=0.1,
                               range_max=8.0, mount=Pose2D(0.05, 0.02, 0.5 * math.pi)),
    # A 270-degree SICK-like scan whose mount is yawed 0.3 rad: no beam is special.
    "yawed_270": LidarSpec(n_beams=541, angle_min=-135 * DEG, angle_max=135 * DEG, range_min=0.05, range_max=20.0,
                           mount=Pose2D(0.1, 0.0, 0.3)),
}


def scan_of(lidar: LidarSpec, patches=(), background: float = INF) -> LaserScan:
    """A scan of ``lidar`` reading ``background`` everywhere, then each ``((lo_deg, hi_deg), value)`` in turn.

    Sectors are base-frame angles [deg], counter-clockwise from lo to hi; later patches overwrite earlier ones.
    """
    template = lidar.scan()
    ranges = np.full(template.n_beams, background, dtype=float)
    for (lo, hi), value in patches:
        mask = template.sector_mask(lo * DEG, hi * DEG)
        assert mask.any(), f"patch {lo}..{hi} deg holds no beam of this lidar"
        ranges[mask] = value
    return template.with_ranges(ranges)
