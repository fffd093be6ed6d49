"""The linear studies: the loop's linear model and what it predicts (linearisation,
gain design, a camera's rate and latency, regions of attraction sampled and certified,
the arm at the goal)."""
