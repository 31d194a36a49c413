"""The bounds of the consistency corrections on what the law reads (gcs/fly/consistent.py says
what the corrections are): gcs fly's filter and gcs sim's compiled copy of it both take them from
here, so a sweep corrects the autopilot's estimates as a flight does.

The velocity's correction c follows the reported position's rate minus the reported velocity;
the acceleration's c_a follows the law velocity's rate minus the accelerometer's acceleration.
A pair of samples whose mismatch exceeds the JUMP bound is an estimator reset (the position or
the velocity stepped) and updates nothing; c is kept within the MAX bound per axis.
"""

#: A velocity mismatch above this [m/s, any axis] is a position reset (a jump), not a rate.
VELOCITY_JUMP_MPS = 5.0
#: The largest velocity correction [m/s per axis]: above what PX4 v1.16 SIH's estimates disagree
#: by in formation (its low-passed mismatch reached 0.9 m/s per axis, and passed 0.5 m/s on
#: 4-13 % of the samples), so the filter follows that estimator and bounds a stranger one.
VELOCITY_MAX_MPS = 1.5
#: The acceleration's: a velocity step (an estimator reset) and the largest correction [m/s^2]
#: (a 0.3 rad attitude error reads as 3 m/s^2).
ACCELERATION_JUMP_MPS2 = 30.0
ACCELERATION_MAX_MPS2 = 3.0
