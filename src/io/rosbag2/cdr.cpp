#include "io/rosbag2/cdr.hpp"

#include <cstring>

namespace rcm::cdr {
namespace {

// Reads fields in order; `pos` counts from the first byte after the header.
class Reader {
 public:
  Reader(const std::uint8_t* data, std::size_t size) {
    if (size < 4) throw DecodeError("encapsulation", 0, "message of " + std::to_string(size) + " bytes: too short for a CDR header");
    if (data[0] != 0 || data[1] > 1)
      throw DecodeError("encapsulation", 0,
                        "encapsulation " + hex(data[0]) + " " + hex(data[1]) +
                            " is not plain CDR (00 00 big-endian or 00 01 little-endian); only XCDR1 is read");
    swap_ = (data[1] == 0) != is_big_endian_host();
    body_ = data + 4;
    left_ = size - 4;
  }

  void set_field(const char* field) { field_ = field; }

  template <class T>
  T get() {
    align(sizeof(T));
    need(sizeof(T));
    unsigned char b[sizeof(T)];
    std::memcpy(b, body_ + pos_, sizeof(T));
    if (swap_)
      for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    T v;
    std::memcpy(&v, b, sizeof(T));
    pos_ += sizeof(T);
    return v;
  }

  void get_string(std::string& out) {
    const std::uint32_t n = get<std::uint32_t>();
    if (n == 0) throw DecodeError(field_, pos_, "string length 0: a CDR string counts its terminating NUL");
    need(n);
    if (body_[pos_ + n - 1] != 0) throw DecodeError(field_, pos_ + 4, "string of " + std::to_string(n) + " bytes without its terminating NUL");
    out.assign(reinterpret_cast<const char*>(body_ + pos_), n - 1);
    pos_ += n;
  }

  // A sequence count, checked against the bytes left (each element at least `min_size` bytes).
  std::size_t get_count(std::size_t min_size) {
    const std::uint32_t n = get<std::uint32_t>();
    if (static_cast<std::uint64_t>(n) * min_size > left_ - pos_)
      throw DecodeError(field_, pos_,
                        "sequence of " + std::to_string(n) + " elements, but only " + std::to_string(left_ - pos_) +
                            " bytes are left");
    return n;
  }

  void get_doubles(std::vector<double>& out) {
    const std::size_t n = get_count(8);
    out.resize(n);
    for (std::size_t i = 0; i < n; ++i) out[i] = get<double>();
  }

  void finish() const {
    // The rmw layers pad a message to a multiple of 4 (or 8) bytes; more is not this type.
    if (left_ - pos_ >= 8)
      throw DecodeError("(end)", pos_ + 4,
                        std::to_string(left_ - pos_) + " bytes after the last field: not this message type?");
  }

 private:
  static bool is_big_endian_host() {
    const std::uint16_t one = 1;
    unsigned char b;
    std::memcpy(&b, &one, 1);
    return b == 0;
  }
  static std::string hex(unsigned v) {
    const char* d = "0123456789abcdef";
    return std::string{d[(v >> 4) & 15], d[v & 15]};
  }
  void align(std::size_t n) {
    const std::size_t pad = (n - pos_ % n) % n;
    need(pad);
    pos_ += pad;
  }
  void need(std::size_t n) const {
    if (n > left_ - pos_)
      throw DecodeError(field_, pos_ + 4,
                        "needs " + std::to_string(n) + " bytes, the message ends after " + std::to_string(left_ - pos_));
  }

  const std::uint8_t* body_ = nullptr;
  std::size_t left_ = 0, pos_ = 0;
  bool swap_ = false;
  const char* field_ = "";
};

void read_header(Reader& r, Header& h) {
  r.set_field("header.stamp.sec");
  h.sec = r.get<std::int32_t>();
  r.set_field("header.stamp.nanosec");
  h.nanosec = r.get<std::uint32_t>();
  if (h.nanosec >= 1000000000u)
    throw DecodeError("header.stamp.nanosec", 8, std::to_string(h.nanosec) + " is not below 10^9");
  r.set_field("header.frame_id");
  r.get_string(h.frame_id);
}

class Writer {
 public:
  explicit Writer(bool big_endian) : swap_(big_endian != host_big()) {
    out_ = {0, static_cast<std::uint8_t>(big_endian ? 0 : 1), 0, 0};
  }
  template <class T>
  void put(T v) {
    while ((out_.size() - 4) % sizeof(T) != 0) out_.push_back(0);
    unsigned char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    if (swap_)
      for (std::size_t i = 0; i < sizeof(T) / 2; ++i) std::swap(b[i], b[sizeof(T) - 1 - i]);
    out_.insert(out_.end(), b, b + sizeof(T));
  }
  void put_string(const std::string& s) {
    put(static_cast<std::uint32_t>(s.size() + 1));
    out_.insert(out_.end(), s.begin(), s.end());
    out_.push_back(0);
  }
  void put_doubles(const std::vector<double>& v) {
    put(static_cast<std::uint32_t>(v.size()));
    for (double x : v) put(x);
  }
  void put_header(const Header& h) {
    put(h.sec);
    put(h.nanosec);
    put_string(h.frame_id);
  }
  std::vector<std::uint8_t> take() {
    while (out_.size() % 4 != 0) out_.push_back(0);
    return std::move(out_);
  }

 private:
  static bool host_big() {
    const std::uint16_t one = 1;
    unsigned char b;
    std::memcpy(&b, &one, 1);
    return b == 0;
  }
  bool swap_;
  std::vector<std::uint8_t> out_;
};

}  // namespace

DecodeError::DecodeError(std::string field, std::size_t offset, const std::string& what)
    : std::runtime_error(what), field_(std::move(field)), offset_(offset) {}

void decode(const std::uint8_t* data, std::size_t size, JointState& m) {
  Reader r(data, size);
  read_header(r, m.header);
  r.set_field("name");
  const std::size_t n = r.get_count(5);  // a string is at least its length and NUL
  m.name.resize(n);
  for (std::size_t i = 0; i < n; ++i) r.get_string(m.name[i]);
  r.set_field("position");
  r.get_doubles(m.position);
  r.set_field("velocity");
  r.get_doubles(m.velocity);
  r.set_field("effort");
  r.get_doubles(m.effort);
  r.finish();
}

void decode(const std::uint8_t* data, std::size_t size, WrenchStamped& m) {
  Reader r(data, size);
  read_header(r, m.header);
  static const char* const fields[6] = {"wrench.force.x",  "wrench.force.y",  "wrench.force.z",
                                        "wrench.torque.x", "wrench.torque.y", "wrench.torque.z"};
  for (int i = 0; i < 6; ++i) {
    r.set_field(fields[i]);
    (i < 3 ? m.force[i] : m.torque[i - 3]) = r.get<double>();
  }
  r.finish();
}

std::vector<std::uint8_t> encode(const JointState& m, bool big_endian) {
  Writer w(big_endian);
  w.put_header(m.header);
  w.put(static_cast<std::uint32_t>(m.name.size()));
  for (const auto& s : m.name) w.put_string(s);
  w.put_doubles(m.position);
  w.put_doubles(m.velocity);
  w.put_doubles(m.effort);
  return w.take();
}

std::vector<std::uint8_t> encode(const WrenchStamped& m, bool big_endian) {
  Writer w(big_endian);
  w.put_header(m.header);
  for (double v : m.force) w.put(v);
  for (double v : m.torque) w.put(v);
  return w.take();
}

}  // namespace rcm::cdr
