#include "rcm/io/joint_state_map.hpp"

#include <algorithm>
#include <cmath>
#include <set>
#include <sstream>
#include <stdexcept>

#include "rcm/common/error.hpp"

namespace rcm {
namespace {

using Defect = JointStateDefect;

Defect make_defect(Defect::Kind kind, const char* array) {
  Defect d;
  d.kind = kind;
  d.array = array;
  return d;
}

}  // namespace

JointStateMap::JointStateMap(std::vector<std::string> names) : names_(std::move(names)) {
  if (names_.empty()) throw std::invalid_argument("JointStateMap: no joint names (use make_positional)");
  std::set<std::string> seen;
  for (const auto& n : names_) {
    if (n.empty()) throw std::invalid_argument("JointStateMap: empty joint name");
    if (!seen.insert(n).second) throw std::invalid_argument("JointStateMap: joint name '" + n + "' given twice");
  }
  num_joints_ = static_cast<int>(names_.size());
}

JointStateMap JointStateMap::make_positional(int num_joints, int message_size) {
  if (num_joints <= 0) throw std::invalid_argument("JointStateMap: positional map needs at least one joint");
  if (message_size == 0) message_size = num_joints;
  if (message_size < num_joints) throw std::invalid_argument("JointStateMap: message size below the joints read");
  JointStateMap m;
  m.num_joints_ = num_joints;
  m.message_size_ = message_size;
  return m;
}

JointStateMap JointStateMap::make_from_message(const JointStateView& message, int max_joints) {
  const auto n = static_cast<int>(message.name.empty() ? message.position.size() : message.name.size());
  const int read = max_joints > 0 ? std::min(n, max_joints) : n;
  if (!message.name.empty())
    return JointStateMap(std::vector<std::string>(message.name.begin(), message.name.begin() + read));
  return make_positional(read, n);
}

JointStateMap::Workspace JointStateMap::create_workspace() const {
  Workspace ws;
  const auto n = static_cast<std::size_t>(num_joints_);
  ws.position.assign(n, 0.0);
  ws.velocity.assign(n, 0.0);
  ws.effort.assign(n, 0.0);
  ws.source.resize(n);
  for (std::size_t j = 0; j < n; ++j) ws.source[j] = j;
  return ws;
}

JointStateDefect JointStateMap::compute_sample(Workspace& ws, const JointStateView& m) const {
  const std::vector<double>* arrays[3] = {&m.position, &m.velocity, &m.effort};
  const char* array_names[3] = {"position", "velocity", "effort"};
  for (int a = 0; a < 3; ++a)
    if (arrays[a]->empty()) return make_defect(Defect::Kind::missing_array, array_names[a]);

  const std::size_t J = static_cast<std::size_t>(num_joints_);
  if (!m.name.empty()) {
    for (int a = 0; a < 3; ++a)
      if (arrays[a]->size() != m.name.size()) {
        Defect d = make_defect(Defect::Kind::lengths, array_names[a]);
        d.size = arrays[a]->size();
        d.expected = m.name.size();
        return d;
      }
  } else {
    const std::size_t expected = by_name() ? m.position.size() : static_cast<std::size_t>(message_size_);
    for (int a = 0; a < 3; ++a)
      if (arrays[a]->size() != expected) {
        Defect d = make_defect(Defect::Kind::lengths, array_names[a]);
        d.size = arrays[a]->size();
        d.expected = expected;
        return d;
      }
  }

  if (by_name()) {
    if (m.name.empty()) return make_defect(Defect::Kind::missing_names, "name");
    // Fast path: the same order as the last message.
    bool same = true;
    for (std::size_t j = 0; j < J && same; ++j)
      same = ws.source[j] < m.name.size() && m.name[ws.source[j]] == names_[j];
    if (!same) {
      for (std::size_t j = 0; j < J; ++j) {
        std::size_t found = m.name.size();
        for (std::size_t i = 0; i < m.name.size(); ++i) {
          if (m.name[i] != names_[j]) continue;
          if (found != m.name.size()) {
            Defect d = make_defect(Defect::Kind::duplicate_name, "name");
            d.index = i;
            d.joint = static_cast<int>(j);
            return d;
          }
          found = i;
        }
        if (found == m.name.size()) {
          Defect d = make_defect(Defect::Kind::missing_joint, "name");
          d.joint = static_cast<int>(j);
          return d;
        }
        ws.source[j] = found;
      }
    }
  }

  for (std::size_t j = 0; j < J; ++j) {
    const std::size_t i = by_name() ? ws.source[j] : j;
    double* out[3] = {&ws.position[j], &ws.velocity[j], &ws.effort[j]};
    for (int a = 0; a < 3; ++a) {
      const double v = (*arrays[a])[i];
      if (!std::isfinite(v)) {
        Defect d = make_defect(Defect::Kind::not_finite, array_names[a]);
        d.index = i;
        d.joint = static_cast<int>(j);
        return d;
      }
      *out[a] = v;
    }
  }
  return {};
}

std::string JointStateMap::describe(const JointStateDefect& d, const JointStateView& m) const {
  auto joint_name = [&](int j) {
    return by_name() && j >= 0 && j < num_joints_ ? "'" + names_[static_cast<std::size_t>(j)] + "'"
                                                  : "joint " + std::to_string(j + 1);
  };
  std::ostringstream s;
  switch (d.kind) {
    case Defect::Kind::none:
      return "no defect";
    case Defect::Kind::missing_array:
      s << d.array << ": missing (empty array); the estimator needs position, velocity and effort";
      break;
    case Defect::Kind::lengths:
      s << d.array << ": " << d.size << " entries, expected " << d.expected
        << (m.name.empty() ? (by_name() ? " (as position)" : " (the number of joints of the first message)")
                           : " (as name)");
      break;
    case Defect::Kind::missing_names:
      s << "name: missing; the joints are ordered by name (" << names_.size() << " names: " << names_.front()
        << ", ...) and this message has none";
      break;
    case Defect::Kind::missing_joint:
      s << "name: missing joint " << joint_name(d.joint) << " (the message names " << m.name.size() << " joints)";
      break;
    case Defect::Kind::duplicate_name:
      s << "name[" << d.index << "]: joint " << joint_name(d.joint) << " named twice";
      break;
    case Defect::Kind::not_finite: {
      const double v = (d.array[0] == 'p' ? m.position : d.array[0] == 'v' ? m.velocity : m.effort)[d.index];
      s << d.array << "[" << d.index << "]";
      if (!m.name.empty() && d.index < m.name.size()) s << " (" << quote_token(m.name[d.index]) << ")";
      s << ": expected a finite number, got " << v;
      break;
    }
  }
  return s.str();
}

}  // namespace rcm
