#include "rcm/dynamics/travel_terms.hpp"

#include <algorithm>

#include "rcm/dynamics/linear_model.hpp"

namespace rcm::dynamics {

void compute_travel_regressor(double q, double lo, double hi, const double* z, int elements, int torque_knots,
                              int hysteresis_knots, double* row) {
  const int columns = torque_knots + elements * hysteresis_knots;
  std::fill(row, row + columns, 0.0);
  int k;
  double w;
  compute_knot_weights(q, lo, hi, torque_knots, k, w);
  row[k] = 1.0 - w;
  row[k + 1] = w;
  compute_knot_weights(q, lo, hi, hysteresis_knots, k, w);
  for (int h = 0; h < elements; ++h) {
    double* level = row + torque_knots + h * hysteresis_knots;
    level[k] = (1.0 - w) * z[h];
    level[k + 1] = w * z[h];
  }
}

}  // namespace rcm::dynamics
