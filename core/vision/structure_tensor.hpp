#pragma once

#include <cmath>
#include <optional>

namespace stereod::vision {

/// The aperture problem's test on a window's structure tensor [[sxx, sxy], [sxy, syy]] (its gradients'
/// products, summed over the window): where the smaller eigenvalue is under `ratio` times the larger (an
/// edge, a streak), the angle of the larger one's eigenvector, the way across the edge; nullopt where the
/// window is textured or blank. Shared by the dense flow's cells and the followed feature points.
inline std::optional<double> edge_angle(double sxx, double sxy, double syy, double ratio)
{
	const double mean = 0.5 * (sxx + syy), spread = std::hypot(0.5 * (sxx - syy), sxy);
	const double large = mean + spread, small = mean - spread;
	if (!(large > 0) || small >= ratio * large)
		return std::nullopt;
	return 0.5 * std::atan2(2 * sxy, sxx - syy);
}

} // namespace stereod::vision
