"""The real cell's error sources: the part as made, the robot, the calibration, the material (docs/cell.md)."""
