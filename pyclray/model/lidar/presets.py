"""The LiDAR presets: each sensor's beam elevations as its maker publishes them, the document and
the table they come from, and its default number of columns (firings per revolution at 10 Hz).

The tables are kept as printed, in the maker's laser (channel) order; pyclray.Lidar orders a
preset's beams from the highest down (row 0 of a range image is the top beam) and keeps the maker's
laser number of each row (Lidar.lasers). Every beam starts at the sensor's origin: the makers'
per-laser offsets (a Velodyne calibration's vertical and horizontal offsets, an Ouster's
lidar_origin_to_beam_origin_mm) and per-beam azimuth corrections are left out; a unit's own
calibration differs from the design values by tenths of a degree (give its elevations with
``Lidar(elevations=...)``).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Preset:
    name: str
    elevations: tuple[float, ...]  # degrees, by the maker's laser number
    columns: int  # firings per revolution at 10 Hz (the azimuth step the maker states, rounded)
    source: str  # the document and table the elevations come from


# Velodyne VLP-16: VLP-16 User Manual (Velodyne LiDAR, 63-9243), the table of the vertical angle of
# each laser ID (the data packet chapter): 16 lasers, 2 degrees apart, interleaved. 0.2 degrees
# between firings at 10 Hz: 1800 columns.
VLP_16 = Preset(
    "VLP-16",
    (-15.0, 1.0, -13.0, 3.0, -11.0, 5.0, -9.0, 7.0, -7.0, 9.0, -5.0, 11.0, -3.0, 13.0, -1.0, 15.0),
    1800,
    "Velodyne VLP-16 User Manual (63-9243), the table of laser IDs and their vertical angles",
)

# Velodyne HDL-32E: HDL-32E User's Manual (Velodyne LiDAR, 63-9113), the table of laser IDs and
# vertical angles: 32 lasers 4/3 degrees apart (printed to two decimals), interleaved. About 0.16
# degrees between firings at 10 Hz: 2250 columns.
HDL_32E = Preset(
    "HDL-32E",
    (-30.67, -9.33, -29.33, -8.00, -28.00, -6.67, -26.67, -5.33, -25.33, -4.00, -24.00, -2.67, -22.67, -1.33,
     -21.33, 0.00, -20.00, 1.33, -18.67, 2.67, -17.33, 4.00, -16.00, 5.33, -14.67, 6.67, -13.33, 8.00, -12.00,
     9.33, -10.67, 10.67),
    2250,
    "Velodyne HDL-32E User's Manual (63-9113), the table of laser IDs and their vertical angles",
)

# Velodyne HDL-64E S2/S3: the HDL-64E S3 User's Manual and Programming Guide (Velodyne LiDAR,
# 63-HDL64ES3), the laser blocks' design angles: the upper block's 32 lasers (laser numbers 0-31)
# from +2 degrees down to -8.33 in steps of 1/3 degree, the lower block's 32 (32-63) from -8.83 down
# to -24.33 in steps of 1/2 degree; each unit ships its own calibration (db.xml) near these. 0.1728
# degrees between firings at 10 Hz: 2083 columns.
HDL_64E = Preset(
    "HDL-64E",
    tuple(2.0 - k / 3.0 for k in range(32)) + tuple(2.0 - 31.0 / 3.0 - 0.5 - k / 2.0 for k in range(32)),
    2083,
    "Velodyne HDL-64E S3 User's Manual and Programming Guide (63-HDL64ES3), the upper and lower laser "
    "blocks' design angles (+2 to -8.33 degrees in 1/3 degree steps, -8.83 to -24.33 in 1/2 degree steps)",
)

# Ouster OS1-64 (gen 1): the design beam_altitude_angles of its sensor metadata (the OS1 Software
# User Guide's beam intrinsics; the Ouster SDK's default metadata, ouster_client's
# gen1_altitude_angles), channel 0 the top beam: 64 beams about 0.527 degrees apart. Lidar mode
# 1024x10 (the default): 1024 columns.
OS1_64 = Preset(
    "OS1-64",
    (16.611, 16.084, 15.557, 15.029, 14.502, 13.975, 13.447, 12.920,
     12.393, 11.865, 11.338, 10.811, 10.283, 9.756, 9.229, 8.701,
     8.174, 7.646, 7.119, 6.592, 6.064, 5.537, 5.010, 4.482,
     3.955, 3.428, 2.900, 2.373, 1.846, 1.318, 0.791, 0.264,
     -0.264, -0.791, -1.318, -1.846, -2.373, -2.900, -3.428, -3.955,
     -4.482, -5.010, -5.537, -6.064, -6.592, -7.119, -7.646, -8.174,
     -8.701, -9.229, -9.756, -10.283, -10.811, -11.338, -11.865, -12.393,
     -12.920, -13.447, -13.975, -14.502, -15.029, -15.557, -16.084, -16.611),
    1024,
    "Ouster OS1-64 sensor metadata, beam_intrinsics.beam_altitude_angles (the gen 1 design values of the "
    "OS1 Software User Guide, as the Ouster SDK's default metadata holds them)",
)

# preset name -> its table (the names as the makers write them)
PRESETS: dict[str, Preset] = {preset.name: preset for preset in (VLP_16, HDL_32E, HDL_64E, OS1_64)}
