"""Joint control on top of the arms' low-level servo: PI loop and joint-offset compensation."""

from suture_bt.control.offset_compensation import (
    command_for_true,
    full_offset,
    true_from_measured,
)
from suture_bt.control.pi_servo import PIGains, PIServo

__all__ = ["PIGains", "PIServo", "command_for_true", "full_offset", "true_from_measured"]
