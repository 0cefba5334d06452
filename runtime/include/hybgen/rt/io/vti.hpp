#pragma once
/// \file vti.hpp
/// VTK XML ImageData (.vti) output of a node-grid field for ParaView/VisIt.
///
/// Axis order: hybgen arrays are C order with the LAST state variable fastest;
/// VTK stores points with x fastest. `write_vti` transposes, so VTK's x, y, z axes
/// are state variables 0, 1, 2 (the same orientation as the heat maps: variable 0
/// horizontal). Grids with fewer than three axes get extent 0 (one point) in the
/// missing ones. The values are written inline as base64 (format="binary",
/// little-endian Float64 with a UInt64 byte-count header), so the file is
/// well-formed XML. VTK has no slot for axis names; they are recorded in an XML
/// comment at the top of the file.

#include <array>
#include <bit>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "hybgen/rt/io/atomic_file.hpp"

namespace hybgen::rt {

namespace detail {

/// Shortest round-trip decimal form of `v` (locale independent).
inline std::string vti_number(double v) {
  char buf[32];
  const auto res = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, res.ptr);
}

/// `s` with the five XML special characters escaped (for attribute values).
inline std::string xml_escape(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (const char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += (static_cast<unsigned char>(c) < 0x20 && c != '\t') ? ' ' : c;
    }
  }
  return out;
}

/// `s` made safe inside an XML comment (no "--", no trailing '-', no control chars).
inline std::string xml_comment_text(std::string_view s) {
  std::string out;
  for (const char c : s) {
    const char d = static_cast<unsigned char>(c) < 0x20 ? ' ' : c;
    if (d == '-' && !out.empty() && out.back() == '-') out += ' ';
    out += d;
  }
  if (!out.empty() && out.back() == '-') out += ' ';
  return out;
}

/// Incremental base64 encoder (RFC 4648, with padding) appending to a string.
class Base64Writer {
 public:
  /// Encodes into `out`.
  explicit Base64Writer(std::string& out) : out_(out) {}
  /// Feeds `n` bytes.
  void write(const void* data, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(data);
    for (std::size_t i = 0; i < n; ++i) {
      buf_[fill_++] = p[i];
      if (fill_ == 3) flush_group();
    }
  }
  /// Emits the final partial group with '=' padding.
  void finish() {
    if (fill_ == 0) return;
    const std::size_t used = fill_;
    while (fill_ < 3) buf_[fill_++] = 0;
    flush_group();
    for (std::size_t i = used + 1; i < 4; ++i) out_[out_.size() - 4 + i] = '=';
  }

 private:
  void flush_group() {
    static constexpr char alphabet[] =
        "ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    const unsigned v = (static_cast<unsigned>(buf_[0]) << 16) |
                       (static_cast<unsigned>(buf_[1]) << 8) | static_cast<unsigned>(buf_[2]);
    out_ += alphabet[(v >> 18) & 63u];
    out_ += alphabet[(v >> 12) & 63u];
    out_ += alphabet[(v >> 6) & 63u];
    out_ += alphabet[v & 63u];
    fill_ = 0;
  }

  std::string& out_;
  std::array<unsigned char, 3> buf_{};
  std::size_t fill_ = 0;
};

/// Appends `v` to the encoder as 8 little-endian bytes.
inline void vti_put_le(Base64Writer& b64, std::uint64_t v) {
  unsigned char bytes[8];
  for (int i = 0; i < 8; ++i) bytes[i] = static_cast<unsigned char>((v >> (8 * i)) & 0xFFu);
  b64.write(bytes, 8);
}

}  // namespace detail

/// One point-data array of a .vti file: its name and C-order values.
struct VtiField {
  std::string name;    ///< Array name (ParaView's "Coloring" list).
  const double* data;  ///< C-order values, the grid's shape.
};

/// Writes scalar fields on a regular node grid as VTK XML ImageData to `path`
/// (atomically). Each field's `data` is a C-order array of shape `dims` (1 to 3 axes,
/// last axis fastest); node i of axis k sits at origins[k] + i * spacings[k]. On output
/// the axes are transposed so that VTK x/y/z = axis 0/1/2 (VTK's x-fastest point order).
/// `axis_names` (one per axis, may be empty) label the axes in an XML comment; the first
/// field is the active scalar. Throws std::invalid_argument for inconsistent arguments and
/// std::runtime_error for I/O errors.
inline void write_vti(const std::string& path, const std::vector<VtiField>& fields,
                      const std::vector<std::size_t>& dims, const std::vector<double>& origins,
                      const std::vector<double>& spacings,
                      const std::vector<std::string>& axis_names) {
  const std::size_t na = dims.size();
  if (na < 1 || na > 3) throw std::invalid_argument("write_vti: 1 to 3 axes supported: " + path);
  if (origins.size() != na || spacings.size() != na ||
      (!axis_names.empty() && axis_names.size() != na))
    throw std::invalid_argument("write_vti: dims, origins, spacings, axis_names disagree");
  std::size_t n = 1;
  for (std::size_t k = 0; k < na; ++k) {
    if (dims[k] == 0) throw std::invalid_argument("write_vti: empty axis in " + path);
    if (!std::isfinite(origins[k]) || !std::isfinite(spacings[k]) || !(spacings[k] > 0.0))
      throw std::invalid_argument("write_vti: origins must be finite and spacings positive");
    if (n > std::numeric_limits<std::size_t>::max() / 8 / dims[k])
      throw std::invalid_argument("write_vti: grid too large");
    n *= dims[k];
  }
  if (fields.empty()) throw std::invalid_argument("write_vti: no field for " + path);
  for (const VtiField& f : fields)
    if (f.data == nullptr) throw std::invalid_argument("write_vti: null data for " + path);

  // Padded to three axes: VTK axis a = our axis a; missing axes have one point.
  std::array<std::size_t, 3> d{1, 1, 1};
  std::array<double, 3> o{0.0, 0.0, 0.0}, sp{1.0, 1.0, 1.0};
  for (std::size_t k = 0; k < na; ++k) {
    d[k] = dims[k];
    o[k] = origins[k];
    sp[k] = spacings[k];
  }
  std::string extent;
  for (std::size_t k = 0; k < 3; ++k) extent += (k ? " 0 " : "0 ") + std::to_string(d[k] - 1);
  const std::string origin =
      detail::vti_number(o[0]) + " " + detail::vti_number(o[1]) + " " + detail::vti_number(o[2]);
  const std::string spacing =
      detail::vti_number(sp[0]) + " " + detail::vti_number(sp[1]) + " " + detail::vti_number(sp[2]);

  std::string xml;
  xml.reserve(fields.size() * (n * 8 * 4 / 3 + 256) + 2048);
  xml += "<?xml version=\"1.0\"?>\n";
  xml += "<!-- hybgen: " + detail::xml_comment_text(fields.front().name) + " on a " +
         std::to_string(na) + "-D node grid; VTK x/y/z = ";
  for (std::size_t k = 0; k < na; ++k) {
    if (k) xml += ", ";
    xml +=
        axis_names.empty() ? "axis " + std::to_string(k) : detail::xml_comment_text(axis_names[k]);
  }
  xml += " -->\n";
  xml +=
      "<VTKFile type=\"ImageData\" version=\"1.0\" byte_order=\"LittleEndian\" "
      "header_type=\"UInt64\">\n";
  xml += "  <ImageData WholeExtent=\"" + extent + "\" Origin=\"" + origin + "\" Spacing=\"" +
         spacing + "\">\n";
  xml += "    <Piece Extent=\"" + extent + "\">\n";
  xml += "      <PointData Scalars=\"" + detail::xml_escape(fields.front().name) + "\">\n";
  for (const VtiField& f : fields) {
    xml += "        <DataArray type=\"Float64\" Name=\"" + detail::xml_escape(f.name) +
           "\" NumberOfComponents=\"1\" format=\"binary\">\n          ";
    // Uncompressed inline binary: one base64 stream of [UInt64 byte count][values].
    detail::Base64Writer b64(xml);
    detail::vti_put_le(b64, static_cast<std::uint64_t>(n) * 8u);
    // VTK point (i, j, k), i fastest  <-  our C-order index (i * d1 + j) * d2 + k.
    for (std::size_t k = 0; k < d[2]; ++k)
      for (std::size_t j = 0; j < d[1]; ++j)
        for (std::size_t i = 0; i < d[0]; ++i)
          detail::vti_put_le(b64, std::bit_cast<std::uint64_t>(f.data[(i * d[1] + j) * d[2] + k]));
    b64.finish();
    xml += "\n        </DataArray>\n";
  }
  xml += "      </PointData>\n";
  xml += "      <CellData>\n      </CellData>\n";
  xml += "    </Piece>\n";
  xml += "  </ImageData>\n";
  xml += "</VTKFile>\n";
  write_file_atomic(path, xml);
}

/// One field: `write_vti` with the single array `field_name`.
inline void write_vti(const std::string& path, const double* data,
                      const std::vector<std::size_t>& dims, const std::vector<double>& origins,
                      const std::vector<double>& spacings,
                      const std::vector<std::string>& axis_names, const std::string& field_name) {
  write_vti(path, {VtiField{field_name, data}}, dims, origins, spacings, axis_names);
}

/// A ParaView collection (.pvd) of `files` (names relative to the .pvd) at `times`: ParaView
/// opens it as one time series.
inline void write_pvd(const std::string& path, const std::vector<std::string>& files,
                      const std::vector<double>& times) {
  if (files.size() != times.size())
    throw std::invalid_argument("write_pvd: files and times disagree: " + path);
  std::string xml =
      "<?xml version=\"1.0\"?>\n<VTKFile type=\"Collection\" version=\"0.1\" "
      "byte_order=\"LittleEndian\">\n  <Collection>\n";
  for (std::size_t k = 0; k < files.size(); ++k)
    xml += "    <DataSet timestep=\"" + detail::vti_number(times[k]) +
           "\" group=\"\" part=\"0\" file=\"" + detail::xml_escape(files[k]) + "\"/>\n";
  xml += "  </Collection>\n</VTKFile>\n";
  write_file_atomic(path, xml);
}

}  // namespace hybgen::rt
