"""Training-data generation from the simulator (front door: may import suture_bt.sim)."""
