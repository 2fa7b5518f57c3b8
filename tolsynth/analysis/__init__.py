"""What a design does: Monte Carlo through the nonlinear kinematics, validation and the closed
loop, the worst pose and the probability map, contributions."""
