"""The studies that run many loops: the baselines compared, Monte-Carlo starts and the
basin of attraction, robustness to a real camera's errors, the camera's accuracy, path
following, and the navigation function's own critical points."""
