// A recording streamed through an online pipeline a chunk at a time (`rcm
// monitor`, the study's online pass): the per-sample path as a live robot
// runs it, and the replay's summary in bounded memory.
//
// The settling time is the one figure that needs the whole run: the last
// sample whose running estimate lies outside a band around the *final*
// estimate. The trace goes to a temporary file as it is made, and the
// replayer keeps at most kMaxSpans bounding boxes of consecutive stretches
// of it; at the end, the stretches whose box lies inside the band are
// skipped and only the last one that does not is read back, from the end.

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <memory>
#include <stdexcept>

#include "rcm/common/error.hpp"
#include "rcm/estimation/online.hpp"

namespace rcm {
namespace {

constexpr std::size_t kMaxSpans = 256;

// One trace record: time and the running misalignment.
struct TracePoint {
  double time;
  double m[3];
};

}  // namespace

struct OnlineReplayer::Trace {
  // Consecutive samples [first, first + count) and the box of their estimates.
  struct Span {
    std::size_t first = 0, count = 0;
    Eigen::Vector3d lo, hi;
  };
  // A member type, not one of this file's anonymous namespace: the Trace
  // declared in the header is a type other files can name.
  struct CloseFile {
    void operator()(std::FILE* f) const { std::fclose(f); }
  };
  std::unique_ptr<std::FILE, CloseFile> file;
  std::vector<Span> spans;
  std::size_t samples = 0;

  void add(double time, const Eigen::Vector3d& m) {
    if (!file) {
      file.reset(std::tmpfile());
      if (!file) throw std::runtime_error("replay_online: cannot create a temporary file for the trace");
    }
    const TracePoint p{time, {m[0], m[1], m[2]}};
    if (std::fwrite(&p, sizeof p, 1, file.get()) != 1)
      throw std::runtime_error("replay_online: cannot write the trace's temporary file (disk full?)");
    // A new span every span_length samples; when there are kMaxSpans, neighbours merge
    // (so spans double in length and their number stays bounded).
    if (spans.empty() || spans.back().count >= span_length) {
      if (spans.size() == kMaxSpans) {
        std::vector<Span> merged;
        merged.reserve(kMaxSpans);
        for (std::size_t i = 0; i + 1 < spans.size(); i += 2) {
          Span s = spans[i];
          s.count += spans[i + 1].count;
          s.lo = s.lo.cwiseMin(spans[i + 1].lo);
          s.hi = s.hi.cwiseMax(spans[i + 1].hi);
          merged.push_back(s);
        }
        spans.swap(merged);
        span_length *= 2;
      }
      if (spans.empty() || spans.back().count >= span_length) spans.push_back({samples, 0, m, m});
    }
    Span& s = spans.back();
    ++s.count;
    s.lo = s.lo.cwiseMin(m);
    s.hi = s.hi.cwiseMax(m);
    ++samples;
  }

  TracePoint read(std::size_t k) const {
    TracePoint p{};
    if (std::fseek(file.get(), static_cast<long>(k * sizeof p), SEEK_SET) != 0 ||
        std::fread(&p, sizeof p, 1, file.get()) != 1)
      throw std::runtime_error("replay_online: cannot read the trace's temporary file back");
    return p;
  }

  // The time of the first sample after the last one outside `band` of `final`
  // (the last sample's time when that is the last one; the first's when none is).
  double get_settled_time(const Eigen::Vector3d& final, double band) const {
    std::vector<TracePoint> block;
    for (std::size_t i = spans.size(); i-- > 0;) {
      const Span& s = spans[i];
      // The box's farthest corner from `final`: inside the band, so is every sample of the span.
      const Eigen::Vector3d far = (s.lo - final).cwiseAbs().cwiseMax((s.hi - final).cwiseAbs());
      if (far.norm() <= band * (1.0 - 1e-12)) continue;
      // Read the span back from its end, a block at a time.
      constexpr std::size_t kBlock = 4096;
      for (std::size_t end = s.first + s.count; end > s.first;) {
        const std::size_t begin = end - std::min(kBlock, end - s.first);
        block.resize(end - begin);
        if (std::fseek(file.get(), static_cast<long>(begin * sizeof(TracePoint)), SEEK_SET) != 0 ||
            std::fread(block.data(), sizeof(TracePoint), block.size(), file.get()) != block.size())
          throw std::runtime_error("replay_online: cannot read the trace's temporary file back");
        for (std::size_t k = block.size(); k-- > 0;) {
          const Eigen::Vector3d m(block[k].m[0], block[k].m[1], block[k].m[2]);
          if ((m - final).norm() > band) {
            const std::size_t outside = begin + k;
            return read(std::min(outside + 1, samples - 1)).time;
          }
        }
        end = begin;
      }
    }
    return read(0).time;
  }

  std::size_t span_length = 1024;
};

OnlineReplayer::OnlineReplayer(const OnlinePipeline& pipeline, const OnlineReplayOptions& options,
                               std::function<void(const OnlineOutput&)> on_sample)
    : pipeline_(pipeline),
      options_(options),
      on_sample_(std::move(on_sample)),
      ws_(pipeline.create_workspace()),
      trace_(std::make_unique<Trace>()) {
  out_.regime.known = pipeline.regime_monitor().known();
}

OnlineReplayer::~OnlineReplayer() = default;

void OnlineReplayer::add(const Recording& r) {
  if (r.num_joints() < pipeline_.model().num_joints()) {
    InputLocation where;
    where.file = r.source;
    throw InputError(where, "the free-space model reads " + std::to_string(pipeline_.model().num_joints()) +
                                " joints, the recording has " + std::to_string(r.num_joints()));
  }
  const Eigen::Index T = r.time.size();
  // Row-major copies so that each sample is contiguous, as from a live topic.
  q_ = r.position;
  qd_ = r.velocity;
  effort_ = r.effort;
  for (Eigen::Index t = 0; t < T; ++t) {
    const auto start = std::chrono::steady_clock::now();
    const OnlineOutput& o =
        pipeline_.compute_sample(ws_, r.time(t), q_.row(t).data(), qd_.row(t).data(), effort_.row(t).data());
    const double took = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    total_s_ += took;
    out_.max_update_s = std::max(out_.max_update_s, took);
    trace_->add(r.time(t), o.misalignment_m);
    if (!out_.motion_start_s && std::hypot(r.velocity(t, 0), r.velocity(t, 1)) > options_.motion_speed)
      out_.motion_start_s = r.time(t);
    // What follows counts estimates, each once (a model whose torque trails
    // brings none for its delay's first samples, or after a long gap).
    if (o.updates == updates_) continue;
    out_.estimates += static_cast<std::size_t>(o.updates - updates_);
    updates_ = o.updates;
    if (o.onset && !out_.onset_s) out_.onset_s = o.onset_time;
    if (o.alarm_raised) out_.alarms.push_back({o.time, std::nullopt, o.force_norm_n});
    if (o.alarm && !out_.alarms.empty())
      out_.alarms.back().peak_force_n = std::max(out_.alarms.back().peak_force_n, o.force_norm_n);
    if (o.alarm_cleared && !out_.alarms.empty()) out_.alarms.back().cleared_s = o.time;
    out_.peak_force_n = std::max(out_.peak_force_n, o.force_norm_n);
    out_.regime.add(o.time, o.regime_flags);
    if (on_sample_) on_sample_(o);
  }
  out_.samples += static_cast<std::size_t>(T);
}

OnlineReplay OnlineReplayer::finish() {
  OnlineReplay out = out_;
  const std::size_t T = out.samples;
  out.mean_update_s = T > 0 ? total_s_ / static_cast<double>(T) : 0.0;
  out.final_output = get_online_output(ws_.estimator);
  if (out.motion_start_s && T > 0) {
    const double settled_at = trace_->get_settled_time(out.final_output.misalignment_m, options_.settle_band_m);
    out.settled_after_s = std::max(0.0, settled_at - *out.motion_start_s);
  }
  return out;
}

OnlineReplay replay_online(const OnlinePipeline& pipeline, const Recording& recording,
                           const OnlineReplayOptions& options,
                           const std::function<void(const OnlineOutput&)>& on_sample) {
  OnlineReplayer replayer(pipeline, options, on_sample);
  replayer.add(recording);
  return replayer.finish();
}

}  // namespace rcm
