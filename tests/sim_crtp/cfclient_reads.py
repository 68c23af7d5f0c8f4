"""What the Crazyflie client (cfclient 2024-2025) reads from a Crazyflie on connect: its flight
tab (attitude indicator, thrust, motor bars, arm button), pose logger, battery bar, supervisor
state and tuning tab. Missing log variables leave the flight tab blank; a missing ``deck``
parameter group raises ``KeyError: 'deck'`` in cfclient."""

CFCLIENT_LOG_VARIABLES = (
    "stabilizer.roll", "stabilizer.pitch", "stabilizer.yaw", "stabilizer.thrust",
    "motor.m1", "motor.m2", "motor.m3", "motor.m4",
    "stateEstimate.x", "stateEstimate.y", "stateEstimate.z",
    "stateEstimate.roll", "stateEstimate.pitch", "stateEstimate.yaw",
    "pm.vbat", "pm.state", "pm.batteryLevel",
    "supervisor.info", "sys.canfly", "sys.isFlying", "sys.isTumbled",
    "controller.roll", "controller.pitch", "controller.yaw",
    "controller.rollRate", "controller.pitchRate", "controller.yawRate",
    "controller.cmd_thrust", "controller.cmd_roll", "controller.cmd_pitch", "controller.cmd_yaw",
    "controller.r_roll", "controller.r_pitch", "controller.r_yaw",
    "controller.accelz", "controller.actuatorThrust",
    "acc.x", "acc.y", "acc.z", "gyro.x", "gyro.y", "gyro.z",
)
CFCLIENT_DECKS = ("bcFlow", "bcFlow2", "bcLighthouse4", "bcLoco", "bcDWM1000")
"""``deck.*`` parameters cfclient reads to enable command-based flight."""
CFCLIENT_PARAMS = ("commander.enHighLevel", "stabilizer.estimator", "stabilizer.controller",
                   "pid_attitude.roll_kp", "pid_rate.roll_kp")
