"""The test rig chain (delay, servo, load cell) and the actuator's limits."""
