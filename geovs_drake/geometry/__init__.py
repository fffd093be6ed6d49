"""Layer 1, pure math: the camera map, its Jacobian, the safe domain, the navigation
function and SO(3) helpers. No systems framework; every formula is scalar-generic
(float, float batches, AutoDiffXd, Expression)."""
