// Recordings and sessions (rcm-session/1, docs/formats.md).

#include <optional>

#include "common.hpp"
#include "rcm/io/recording.hpp"
#include "rcm/io/recording_reader.hpp"
#include "rcm/io/rosbag2.hpp"
#include "rcm/io/session.hpp"

namespace rcm::python {

namespace {

RecordingReadOptions make_read_options(bool dedupe, std::optional<double> assumed_rate_hz, int min_joints) {
  RecordingReadOptions o;
  o.dedupe = dedupe;
  if (assumed_rate_hz) {
    if (!(*assumed_rate_hz > 0) || !std::isfinite(*assumed_rate_hz))
      throw InputError(argument_location("rcm.load_recording", "assumed_rate_hz"), "must be a positive number");
    o.assumed_rate_hz = assumed_rate_hz;
  }
  o.min_joints = min_joints;
  return o;
}

// A recording from arrays, checked exactly as the reader checks a file.
Recording make_recording(py::handle time, py::handle position, py::handle velocity, py::handle effort,
                         py::handle force, const std::string& source) {
  const std::string fn = "rcm.Recording";
  Recording r;
  r.source = source;
  r.layout = RecordingLayout::in_memory;
  // Finiteness is left to validate_recording, whose message names the sample.
  r.time = to_vector(time, argument_location(fn, "time"), -1, false);
  const Eigen::Index T = r.time.size();
  r.position = to_matrix(position, argument_location(fn, "position"), T, -1, false);
  const Eigen::Index N = r.position.cols();
  r.velocity = to_matrix(velocity, argument_location(fn, "velocity"), T, N, false);
  r.effort = to_matrix(effort, argument_location(fn, "effort"), T, N, false);
  if (!force.is_none()) r.force = to_matrix(force, argument_location(fn, "force"), T, 3, false);
  validate_recording(r);
  return r;
}

py::dict summary_to_dict(const RecordingSummary& s) {
  auto ranges = [](const std::vector<RecordingSummary::Range>& v) {
    py::list out;
    for (const auto& r : v) out.append(py::make_tuple(r.min, r.max));
    return out;
  };
  py::dict d;
  d["samples"] = s.samples;
  d["joints"] = s.joints;
  d["duration_s"] = s.duration_s;
  d["rate_hz"] = s.rate_hz;
  d["dt_median_s"] = s.dt_median_s;
  d["dt_min_s"] = s.dt_min_s;
  d["dt_max_s"] = s.dt_max_s;
  d["jitter_s"] = s.jitter_s;
  d["repeated_rows"] = s.repeated_rows;
  d["repeated_rows_removed"] = s.repeated_rows_removed;
  d["has_force"] = s.has_force;
  d["time_from_rate"] = s.time_from_rate;
  d["position"] = ranges(s.position);
  d["velocity"] = ranges(s.velocity);
  d["effort"] = ranges(s.effort);
  d["force"] = ranges(s.force);
  return d;
}

}  // namespace

void bind_io(py::module_& m) {
  // The module links rcm::core only; without this a .bag would reach the CSV
  // parser and fail with a message about its first line.
  register_recording_reader(".bag", [](const std::filesystem::path& path, const RecordingReadOptions&) -> Recording {
    InputLocation where;
    where.file = path.string();
    throw InputError(where, "a ROS 1 bag: the Python module reads CSV and rosbag2 recordings; convert it with "
                            "`rcm convert FILE.bag FILE.csv [--topic T]` (the rcm CLI built with ROS)");
  });
  py::enum_<RecordingLayout>(m, "RecordingLayout", "Where a recording came from")
      .value("rcm_csv", RecordingLayout::rcm_csv, "the contract's CSV (time, position_i, velocity_i, effort_i, force_x..z)")
      .value("rostopic_csv", RecordingLayout::rostopic_csv, "`rostopic echo -p /PSM1/measured_js` output")
      .value("in_memory", RecordingLayout::in_memory, "built from arrays")
      .value("rosbag", RecordingLayout::rosbag, "a ROS 1 bag's JointState topic")
      .value("rosbag2", RecordingLayout::rosbag2, "a rosbag2 recording's JointState topic (SQLite or MCAP)");

  py::class_<Recording, std::shared_ptr<Recording>>(
      m, "Recording",
      "One recording: time-stamped joint positions, velocities and efforts of N >= 3 joints, optionally the\n"
      "ground-truth force at the incision (base frame). Immutable once built: the array attributes are\n"
      "read-only views (take .copy() to edit, then build a new Recording).")
      .def(py::init(&make_recording), py::arg("time"), py::arg("position"), py::arg("velocity"), py::arg("effort"),
           py::arg("force") = py::none(), py::arg("source") = "<numpy>",
           "Build from arrays: time (T,) in s, position/velocity/effort (T, N), force (T, 3) or None.\n"
           "Validated like a file: N >= 3, sizes agree, every value finite, time strictly increasing;\n"
           "rcm.InputError names `source`, the array (e.g. position_2) and the sample otherwise.\n"
           "Arrays are copied; float32 and exactly representable integers are widened to float64,\n"
           "anything else (bool, complex, 1-D where 2-D is expected...) is refused.")
      .def_property_readonly("time", [](py::object self) { return readonly_view(self.cast<const Recording&>().time, self); },
                             "(T,) s, strictly increasing")
      .def_property_readonly("position", [](py::object self) { return readonly_view(self.cast<const Recording&>().position, self); },
                             "(T, N): rad, rad, m, rad...")
      .def_property_readonly("velocity", [](py::object self) { return readonly_view(self.cast<const Recording&>().velocity, self); },
                             "(T, N): rad/s, rad/s, m/s, rad/s...")
      .def_property_readonly("effort", [](py::object self) { return readonly_view(self.cast<const Recording&>().effort, self); },
                             "(T, N): N m, N m, N, N m... (measured actuator effort)")
      .def_property_readonly("force",
                             [](py::object self) -> py::object {
                               const Recording& r = self.cast<const Recording&>();
                               if (!r.force) return py::none();
                               return readonly_view(*r.force, self);
                             },
                             "(T, 3) N, base frame (ground truth, evaluation only), or None")
      .def_property_readonly("line", [](const Recording& r) { return py::array_t<std::size_t>(static_cast<py::ssize_t>(r.line.size()), r.line.data()); },
                             "1-based source line of every sample (empty for in-memory recordings)")
      .def_readonly("source", &Recording::source)
      .def_readonly("layout", &Recording::layout)
      .def_readonly("repeated_rows", &Recording::repeated_rows, "rows repeating the previous one (counted always)")
      .def_readonly("repeated_rows_removed", &Recording::repeated_rows_removed)
      .def_readonly("time_from_rate", &Recording::time_from_rate, "time built from assumed_rate_hz")
      .def_property_readonly("num_samples", &Recording::num_samples)
      .def_property_readonly("num_joints", &Recording::num_joints)
      .def_property_readonly("has_force", &Recording::has_force)
      .def("__len__", &Recording::num_samples)
      .def("__repr__", [](const Recording& r) {
        return "<rcm.Recording '" + r.source + "': " + std::to_string(r.num_samples()) + " samples, " +
               std::to_string(r.num_joints()) + " joints" + (r.has_force() ? ", force" : "") + ">";
      });

  m.def("load_recording",
        [](const std::filesystem::path& path, bool dedupe, std::optional<double> rate, int min_joints,
           std::optional<std::string> topic, std::optional<std::string> force_topic, const std::string& time) {
          const RecordingReadOptions o = make_read_options(dedupe, rate, min_joints);
          if (time != "header" && time != "receive")
            throw InputError(argument_location("rcm.load_recording", "time"), "'header' or 'receive', got '" + time + "'");
          const bool bag_options = topic || force_topic || time != "header";
          if (!is_rosbag2_path(path)) {
            if (bag_options)
              throw InputError(argument_location("rcm.load_recording", topic ? "topic" : force_topic ? "force_topic" : "time"),
                               "applies to rosbag2 recordings (a bag directory, .db3 or .mcap), not to " + path.string());
            py::gil_scoped_release release;
            return std::make_shared<Recording>(load_recording(path, o));
          }
          TopicReadOptions t;
          t.read = o;
          if (topic) t.topic = *topic;
          if (force_topic) t.force_topic = *force_topic;
          t.time = time == "receive" ? MessageTime::receive : MessageTime::header;
          Rosbag2ReadInfo info;
          std::shared_ptr<Recording> rec;
          {
            py::gil_scoped_release release;
            rec = std::make_shared<Recording>(load_rosbag2_recording(path, t, &info));
          }
          for (const std::string& w : info.warnings) PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1);
          return rec;
        },
        py::arg("path"), py::kw_only(), py::arg("dedupe") = false, py::arg("assumed_rate_hz") = py::none(),
        py::arg("min_joints") = 3, py::arg("topic") = py::none(), py::arg("force_topic") = py::none(),
        py::arg("time") = "header",
        "Read and validate a recording: the contract's CSV, `rostopic echo -p /PSM1/measured_js` output, or a\n"
        "rosbag2 recording (a bag directory, .db3 or .mcap; no ROS 2 needed).\n"
        "dedupe: drop rows repeating the previous one; assumed_rate_hz: sampling rate of a file without a\n"
        "time column (never invented otherwise). rosbag2 only: topic (sensor_msgs/msg/JointState, default\n"
        "/PSM1/measured_js), force_topic (geometry_msgs/msg/WrenchStamped read as the force columns), time\n"
        "('header': header.stamp, zero-stamp messages skipped as invalid data; 'receive': the recorder's\n"
        "clock); a cut-off MCAP file is read up to its last complete record with a UserWarning.\n"
        "rcm.InputError names file, line and column (or topic, message and field) of any defect.");
  m.def("parse_recording",
        [](const std::string& text, const std::string& source, bool dedupe, std::optional<double> rate, int min_joints) {
          const RecordingReadOptions o = make_read_options(dedupe, rate, min_joints);
          py::gil_scoped_release release;
          return std::make_shared<Recording>(parse_recording(text, source, o));
        },
        py::arg("text"), py::arg("source") = "<text>", py::kw_only(), py::arg("dedupe") = false,
        py::arg("assumed_rate_hz") = py::none(), py::arg("min_joints") = 3,
        "Same as load_recording, from CSV text in memory; `source` names it in error messages.");
  // A recording as a stream of chunks: each a Recording of at most chunk_rows samples.
  py::class_<RecordingReader>(
      m, "RecordingChunks",
      "The chunks of one recording (rcm.iter_recording): iterate to get rcm.Recording blocks of at most\n"
      "chunk_rows consecutive samples, each with time, position, velocity, effort and force as numpy arrays.")
      .def("__iter__", [](py::object self) { return self; })
      .def("__next__", [](RecordingReader& r) {
        auto chunk = std::make_shared<Recording>();
        bool more;
        {
          py::gil_scoped_release release;
          more = r.read_chunk(*chunk);
        }
        if (!more) throw py::stop_iteration();
        return chunk;
      })
      .def_property_readonly("source", &RecordingReader::source)
      .def_property_readonly("layout", &RecordingReader::layout)
      .def_property_readonly("num_joints", &RecordingReader::num_joints)
      .def_property_readonly("has_force", &RecordingReader::has_force)
      .def_property_readonly("chunk_rows", &RecordingReader::chunk_rows)
      .def_property_readonly("samples_read", &RecordingReader::samples_read, "samples handed out so far")
      .def_property_readonly("repeated_rows", &RecordingReader::repeated_rows,
                             "repeated rows met so far (the total once exhausted)");
  m.def("iter_recording",
        [](const std::filesystem::path& path, std::size_t chunk_rows, bool dedupe, std::optional<double> rate,
           int min_joints, std::optional<std::string> topic, std::optional<std::string> force_topic,
           const std::string& time) -> std::unique_ptr<RecordingReader> {
          const RecordingReadOptions o = make_read_options(dedupe, rate, min_joints);
          if (chunk_rows == 0)
            throw InputError(argument_location("rcm.iter_recording", "chunk_rows"), "must be at least 1");
          if (time != "header" && time != "receive")
            throw InputError(argument_location("rcm.iter_recording", "time"), "'header' or 'receive', got '" + time + "'");
          const bool bag_options = topic || force_topic || time != "header";
          if (!is_rosbag2_path(path)) {
            if (bag_options)
              throw InputError(argument_location("rcm.iter_recording", topic ? "topic" : force_topic ? "force_topic" : "time"),
                               "applies to rosbag2 recordings (a bag directory, .db3 or .mcap), not to " + path.string());
            py::gil_scoped_release release;
            return open_recording(path, o, chunk_rows);
          }
          TopicReadOptions t;
          t.read = o;
          if (topic) t.topic = *topic;
          if (force_topic) t.force_topic = *force_topic;
          t.time = time == "receive" ? MessageTime::receive : MessageTime::header;
          std::unique_ptr<Rosbag2RecordingReader> reader;
          {
            py::gil_scoped_release release;
            reader = open_rosbag2_recording(path, t, chunk_rows);
          }
          reader->set_on_end([](RecordingReader& r) {
            const py::gil_scoped_acquire acquire;
            for (const std::string& w : static_cast<Rosbag2RecordingReader&>(r).info().warnings)
              PyErr_WarnEx(PyExc_UserWarning, w.c_str(), 1);
          });
          return reader;
        },
        py::arg("path"), py::arg("chunk_rows") = kDefaultChunkRows, py::kw_only(), py::arg("dedupe") = false,
        py::arg("assumed_rate_hz") = py::none(), py::arg("min_joints") = 3, py::arg("topic") = py::none(),
        py::arg("force_topic") = py::none(), py::arg("time") = "header",
        "Read a recording as load_recording does, as an iterator of rcm.Recording chunks of at most chunk_rows\n"
        "samples: memory does not grow with the recording's length. The chunks concatenated are exactly\n"
        "load_recording's arrays; the same checks, and rcm.InputError names the line (or message) of a defect\n"
        "when the iteration reaches it. Same keywords as load_recording.");
  m.def("save_recording",
        [](const std::filesystem::path& path, const Recording& r) {
          py::gil_scoped_release release;
          save_recording(path, r);
        },
        py::arg("path"), py::arg("recording"),
        "Write the contract's CSV layout atomically, with shortest round-trip numbers (reading back is exact).");
  m.def("validate_recording", &validate_recording, py::arg("recording"),
        "Check the invariants (sizes, finiteness, increasing time); raises rcm.InputError.");

  py::class_<RecordingSummary>(m, "RecordingSummary", "What `rcm inspect` shows of a recording")
      .def_readonly("samples", &RecordingSummary::samples)
      .def_readonly("joints", &RecordingSummary::joints)
      .def_readonly("duration_s", &RecordingSummary::duration_s)
      .def_readonly("rate_hz", &RecordingSummary::rate_hz, "1 / median sampling interval")
      .def_readonly("dt_median_s", &RecordingSummary::dt_median_s)
      .def_readonly("dt_min_s", &RecordingSummary::dt_min_s)
      .def_readonly("dt_max_s", &RecordingSummary::dt_max_s)
      .def_readonly("jitter_s", &RecordingSummary::jitter_s, "standard deviation of the sampling interval")
      .def_readonly("repeated_rows", &RecordingSummary::repeated_rows)
      .def_readonly("repeated_rows_removed", &RecordingSummary::repeated_rows_removed)
      .def_readonly("has_force", &RecordingSummary::has_force)
      .def_readonly("time_from_rate", &RecordingSummary::time_from_rate)
      .def("to_dict", &summary_to_dict, "Everything as a dict; ranges as (min, max) per joint")
      .def("__repr__", [](const RecordingSummary& s) {
        return "<rcm.RecordingSummary " + std::to_string(s.samples) + " samples, " + std::to_string(s.joints) +
               " joints, " + std::to_string(s.duration_s) + " s, " + std::to_string(s.rate_hz) + " Hz>";
      });
  m.def("summarize_recording", py::overload_cast<const Recording&>(&summarize_recording), py::arg("recording"),
        "Samples, joints, duration, rate, jitter, repeated rows and per-joint ranges (rcm inspect).");

  py::class_<CalibrationSpec>(m, "CalibrationSpec", "Step 2: teleoperation under a pure, known coaxial offset")
      .def(py::init<>())
      .def_readwrite("recording", &CalibrationSpec::recording)
      .def_readwrite("coaxial_offset_m", &CalibrationSpec::coaxial_offset_m, "the known D*, m");
  py::class_<TrialSpec>(m, "TrialSpec", "One trial of a session: teleoperation (3a) and optional static hold (3b)")
      .def(py::init<>())
      .def_readwrite("name", &TrialSpec::name)
      .def_readwrite("recording", &TrialSpec::recording)
      .def_readwrite("static_recording", &TrialSpec::static_recording, "path or None")
      .def_readwrite("truth_misalignment_m", &TrialSpec::truth_misalignment_m, "[dr_x, dr_y, D] m or None")
      .def("__repr__", [](const TrialSpec& t) { return "<rcm.TrialSpec '" + t.name + "'>"; });
  py::class_<Session>(m, "Session",
                      "An rcm-session/1 manifest with paths resolved against its directory.\n"
                      "List attributes are copies: assign a new list (session.trials = session.trials[:1]) to change them.")
      .def(py::init<>())
      .def_readwrite("manifest", &Session::manifest)
      .def_readwrite("robot", &Session::robot)
      .def_readwrite("q0", &Session::q0, "docking configuration (rad, rad, m)")
      .def_readwrite("free_space", &Session::free_space, "list of free-space recording paths")
      .def_readwrite("baseline", &Session::baseline)
      .def_readwrite("calibration", &Session::calibration, "CalibrationSpec or None")
      .def_readwrite("trials", &Session::trials, "list of TrialSpec")
      .def_property_readonly("extra", [](const Session& s) { return to_python(s.extra); },
                             "unknown top-level fields, kept (dict)")
      .def("__repr__", [](const Session& s) {
        return "<rcm.Session '" + s.manifest.string() + "': " + std::to_string(s.trials.size()) + " trials>";
      });
  m.def("load_session", &load_session, py::arg("manifest"),
        "Read and validate a manifest (format, known robot, q0 within limits, every file present).\n"
        "rcm.InputError names the manifest and the JSON field.");
  m.def("save_session", &save_session, py::arg("manifest"), py::arg("session"),
        "Write a manifest atomically with paths relative to its directory.");
}

}  // namespace rcm::python
