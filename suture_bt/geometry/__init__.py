"""Known geometry of the task (needle model, phantom ports): facts a real system is given."""

from suture_bt.geometry.needle import NeedleModel
from suture_bt.geometry.phantom import PhantomModel, Port

__all__ = ["NeedleModel", "PhantomModel", "Port"]
