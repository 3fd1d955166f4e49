#pragma once
// The data of the tissue-law identification (paper III-C step 2): pairs
// x = D* tan(theta) [m] and y = |f_inc| [N] from a calibration recording under a
// known pure coaxial offset D*, and their CSV form (header "x,y", docs/formats.md).

#include <Eigen/Core>
#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include "rcm/io/recording.hpp"
#include "rcm/kinematics/incision.hpp"

namespace rcm {

struct TissuePairs {
  std::string source;              // file or description, for messages
  Eigen::VectorXd x;               // m
  Eigen::VectorXd y;               // N
  // Where each pair came from: the CSV line of a pairs file, or the source line
  // (or 0-based sample index for in-memory recordings) of the recording sample.
  std::vector<std::size_t> origin;

  std::size_t size() const { return static_cast<std::size_t>(x.size()); }
};

// Throws InputError (naming `pairs.source` and the line) if sizes disagree, a
// value is not finite, there are fewer than `min_pairs` pairs or all x are equal.
void validate_tissue_pairs(const TissuePairs& pairs, std::size_t min_pairs = 4);

// Pairs CSV: a header row naming columns "x" and "y" (any order, other columns
// ignored), one pair per row. Every defect is an InputError naming file, line
// and column: missing column, non-numeric or non-finite cell, short row.
TissuePairs parse_tissue_pairs(const std::string& text, const std::string& source);
TissuePairs load_tissue_pairs(const std::filesystem::path& path);
// Header "x,y", shortest round-trip numbers (reading back is exact), atomic write.
void save_tissue_pairs(const std::filesystem::path& path, const TissuePairs& pairs);

enum class TissueForceSource {
  estimated,  // f_inc = J_D*^{-T} (tau - tau_fs), the paper's method
  measured,   // |force_x,y,z| of the recording: a force sensor, for reference only
};

struct TissuePairOptions {
  // Samples with theta below this carry no information on g: x = D* tan(theta)
  // is ~0 and the force is the torque-noise floor amplified by J_D^{-T}, whose
  // direction is meaningless. 2 degrees: at D* = 30 mm, x < 1 mm.
  double min_theta_rad = 2.0 * 3.14159265358979323846 / 180.0;
  // Samples whose J_D* is flagged ill-conditioned (condition > max_condition)
  // are dropped too, not only singular ones.
  bool drop_ill_conditioned = true;
  JacobianCheckOptions jacobian;
};
const OptionTable<TissuePairOptions>& get_option_table(OptionTag<TissuePairOptions>);

struct TissuePairsReport {
  std::size_t samples = 0;               // in the recording
  std::size_t kept = 0;
  std::size_t dropped_small_theta = 0;   // theta < min_theta_rad
  std::size_t dropped_singular = 0;      // J_D* singular
  std::size_t dropped_ill_conditioned = 0;
  std::size_t dropped_non_finite = 0;    // force not finite for another reason
};

struct TissuePairsResult {
  TissuePairs pairs;
  TissuePairsReport report;
};

// Pairs from a calibration recording under the known pure coaxial offset D*
// (m): x = D* tan(theta(q0, q)), y = |J_D*^{-T} (tau - tau_fs)|. tau_fs is
// T x (>= 3): the free-space model's prediction for every sample. Throws
// InputError if sizes disagree or tau_fs is not finite. Dropped samples are
// counted in the report, never silently.
TissuePairsResult compute_tissue_pairs(const Recording& recording, const Eigen::MatrixXd& tau_fs,
                                       const Eigen::Vector3d& q0, double D_star,
                                       const TissuePairOptions& options = {});

// Same pairs, with y = |force| from the recording's force columns (a sensor).
// For reference and for checking the estimated pairs; throws InputError if the
// recording has no force columns.
TissuePairsResult compute_tissue_pairs_from_measured_force(const Recording& recording,
                                                           const Eigen::Vector3d& q0,
                                                           double D_star,
                                                           const TissuePairOptions& options = {});

// Denoising by equal-count binning along x: sort by x, cut into `bins` groups of
// (almost) equal size, replace each group by its mean x and mean y. The fit's
// loss then is the MSE over bins. bins >= size() returns the pairs sorted.
TissuePairs compute_binned_pairs(const TissuePairs& pairs, std::size_t bins);

// x rescaled for another assumed offset: x' = x * D_to / D_from (y unchanged).
// Used for the D* +- delta sensitivity when only pairs are available; with a
// recording, recompute the pairs instead (J_D changes y as well).
TissuePairs compute_rescaled_pairs(const TissuePairs& pairs, double D_from, double D_to);

}  // namespace rcm
