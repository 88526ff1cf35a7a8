"""What the wire may carry: plausibility bounds of decoded values, SET_ATTITUDE_TARGET type_mask
bits and the MAV_CMD ids we send. Shared by the decoders (:mod:`mpf_mavlink.mavlink.codec`) and
the encoders (:mod:`mpf_mavlink.mavlink.encode`); imports nothing of this package.
"""

from __future__ import annotations

import math

# Plausibility bounds. Anything beyond them is corruption, a unit bug or a spoof, not flight.
MAX_SPEED_M_S = 200.0  # any velocity component or norm (fixed-wing UAV, wind)
MAX_RATE_RAD_S = 50.0  # ~2900 deg/s, far beyond any airframe
MAX_ANGLE_RAD = 2.0 * math.pi + 1e-3
MAX_LOCAL_POS_M = 1.0e6  # 1000 km from the EKF origin
MIN_ALT_M, MAX_ALT_M = -1000.0, 50000.0
MAX_ACCEL_M_S2 = 200.0  # ~20 g
QUAT_NORM_TOL = 0.1  # |q| must be within 1 +- 0.1 (a float32 unit quaternion is within 1e-6)

# SET_ATTITUDE_TARGET type_mask bits (common.xml ATTITUDE_TARGET_TYPEMASK)
TM_BODY_ROLL_RATE_IGNORE = 1
TM_BODY_PITCH_RATE_IGNORE = 2
TM_BODY_YAW_RATE_IGNORE = 4
TM_THRUST_BODY_SET = 32
TM_THROTTLE_IGNORE = 64
TM_ATTITUDE_IGNORE = 128

#: PX4 offboard body rates: quaternion ignored, the three rates and thrust used.
TYPE_MASK_PX4_RATES = TM_ATTITUDE_IGNORE  # 128
#: ArduPlane GUIDED attitude: roll and pitch from the quaternion, thrust used, yaw left to
#: ArduPlane. ArduPlane's handler (ArduPlane/GCS_MAVLink_Plane.cpp,
#: handle_set_attitude_target) inverts the mask and takes each Euler angle whose rate bit is
#: clear, or all three when the attitude bit is clear; a forced yaw is written straight to the
#: rudder (Attitude.cpp, calc_nav_yaw_coordinated), bypassing its yaw damper and rudder mix
#: (KFF_RDDRMIX), so a yaw of 0 pins the rudder at neutral through every turn. With the
#: attitude bit set and the yaw-rate bit set (132) roll and pitch are forced and the rudder
#: stays ArduPlane's own coordinated-turn output, as in its other modes. ArduPlane never reads
#: the body rates.
TYPE_MASK_ARDUPLANE_ATTITUDE = TM_ATTITUDE_IGNORE | TM_BODY_YAW_RATE_IGNORE  # 132

MAV_CMD_SET_MESSAGE_INTERVAL = 511
MAV_CMD_REQUEST_MESSAGE = 512
MAV_CMD_GET_HOME_POSITION = 410
MAV_CMD_DO_REPOSITION = 192

MAV_CMD_DO_SET_MODE = 176
MAV_CMD_COMPONENT_ARM_DISARM = 400
ARM_FORCE_MAGIC = 21196  # param2 that forces arming/disarming (PX4 and ArduPilot)


def _finite(*vals: float) -> bool:
    # a plain loop: a generator in all() costs three times as much, on every sample decoded
    isfinite = math.isfinite
    try:
        for v in vals:
            if not isfinite(float(v)):
                return False
    except (TypeError, ValueError):
        return False
    return True


def _geodetic_ok(lat: float, lon: float, alt: float) -> bool:
    if not _finite(lat, lon, alt) or abs(lat) > 90.0 or abs(lon) > 180.0:
        return False
    if lat == 0.0 and lon == 0.0:  # what autopilots send before a fix, never a real position
        return False
    return MIN_ALT_M <= alt <= MAX_ALT_M
