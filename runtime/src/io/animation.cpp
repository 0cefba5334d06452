// The animated GIF of a run's frames (hybgen/rt/io/animation.hpp).

#include "hybgen/rt/io/animation.hpp"

#include <gif_lib.h>

#include <algorithm>
#include <array>
#include <limits>
#include <stdexcept>
#include <string>

#include "hybgen/rt/io/colormap.hpp"

namespace hybgen::rt {

namespace {

/// 176 viridis steps, 72 greys from black to white, and the figures' other colours.
std::array<std::uint32_t, 256> make_palette() {
  std::array<std::uint32_t, 256> p{};
  std::size_t n = 0;
  const auto rgb = [](int r, int g, int b) {
    return (static_cast<std::uint32_t>(r) << 16) | (static_cast<std::uint32_t>(g) << 8) |
           static_cast<std::uint32_t>(b);
  };
  for (int i = 0; i < 176; ++i) {
    const auto c = viridis_rgb((i + 0.5) / 176.0);
    p[n++] = rgb(c[0], c[1], c[2]);
  }
  for (int i = 0; i < 72; ++i) {
    const int v = (255 * i + 35) / 71;
    p[n++] = rgb(v, v, v);
  }
  // Guards (and their anti-aliased edges on white and on dark viridis), outside, not a
  // number, and the budget's curve colours.
  for (const std::uint32_t c :
       {rgb(237, 84, 46), rgb(246, 170, 150), rgb(150, 60, 60), rgb(217, 217, 217),
        rgb(255, 0, 255), rgb(0, 115, 179), rgb(230, 158, 0), rgb(0, 158, 115)})
    p[n++] = c;
  return p;
}

const std::array<std::uint32_t, 256>& palette() {
  static const std::array<std::uint32_t, 256> p = make_palette();
  return p;
}

/// Nearest palette entry of every colour quantised to 5 bits per channel (32768 entries).
const std::vector<std::uint8_t>& nearest_table() {
  static const std::vector<std::uint8_t> table = [] {
    std::vector<std::uint8_t> t(32768);
    const auto& p = palette();
    for (int r = 0; r < 32; ++r)
      for (int g = 0; g < 32; ++g)
        for (int b = 0; b < 32; ++b) {
          // The bucket's centre, but its ends at 0 and 255: white stays white, black black.
          const auto centre = [](int q) { return q == 31 ? 255 : q == 0 ? 0 : q * 8 + 4; };
          const int R = centre(r), G = centre(g), B = centre(b);
          int best = 0;
          long best_d = std::numeric_limits<long>::max();
          for (int i = 0; i < 256; ++i) {
            const int pr = static_cast<int>((p[static_cast<std::size_t>(i)] >> 16) & 255);
            const int pg = static_cast<int>((p[static_cast<std::size_t>(i)] >> 8) & 255);
            const int pb = static_cast<int>(p[static_cast<std::size_t>(i)] & 255);
            // Weighted (green counts most), close to perceived differences.
            const long d =
                3L * (R - pr) * (R - pr) + 4L * (G - pg) * (G - pg) + 2L * (B - pb) * (B - pb);
            if (d < best_d) best_d = d, best = i;
          }
          t[static_cast<std::size_t>((r << 10) | (g << 5) | b)] = static_cast<std::uint8_t>(best);
        }
    return t;
  }();
  return table;
}

[[noreturn]] void fail(const std::string& path, int code) {
  throw std::runtime_error("cannot write '" + path + "': " + GifErrorString(code));
}

}  // namespace

std::uint8_t gif_palette_index(std::uint32_t rgb) {
  const std::uint32_t r = (rgb >> 19) & 31, g = (rgb >> 11) & 31, b = (rgb >> 3) & 31;
  return nearest_table()[(r << 10) | (g << 5) | b];
}

std::uint32_t gif_palette_colour(std::uint8_t i) {
  return palette()[i];
}

IndexedFrame quantize(const Raster& r) {
  const std::vector<std::uint8_t>& table = nearest_table();
  IndexedFrame f{r.width, r.height, std::vector<std::uint8_t>(r.pixel.size())};
  for (std::size_t i = 0; i < r.pixel.size(); ++i) {
    const std::uint32_t c = r.pixel[i];
    f.index[i] = table[((c >> 9) & 0x7C00u) | ((c >> 6) & 0x3E0u) | ((c >> 3) & 0x1Fu)];
  }
  return f;
}

void write_gif(const std::string& path, const std::vector<IndexedFrame>& frames, int delay_cs) {
  if (frames.empty()) throw std::invalid_argument("write_gif: no frames for " + path);
  const int w = frames.front().width, h = frames.front().height;
  for (const IndexedFrame& f : frames)
    if (f.width != w || f.height != h ||
        f.index.size() != static_cast<std::size_t>(w) * static_cast<std::size_t>(h))
      throw std::invalid_argument("write_gif: frames of different sizes for " + path);
  int err = 0;
  GifFileType* gif = EGifOpenFileName(path.c_str(), false, &err);
  if (!gif) fail(path, err);
  // Closes the file on every path; EGifCloseFile frees `gif` either way.
  struct Closer {
    GifFileType*& g;
    ~Closer() {
      if (g) {
        int e = 0;
        EGifCloseFile(g, &e);
      }
    }
  } closer{gif};
  const auto check = [&](int status) {
    if (status == GIF_ERROR) fail(path, gif->Error);
  };
  std::array<GifColorType, 256> colours{};
  for (std::size_t i = 0; i < 256; ++i) {
    const std::uint32_t c = palette()[i];
    colours[i] = {static_cast<GifByteType>((c >> 16) & 255),
                  static_cast<GifByteType>((c >> 8) & 255), static_cast<GifByteType>(c & 255)};
  }
  ColorMapObject* map = GifMakeMapObject(256, colours.data());
  if (!map) throw std::runtime_error("cannot write '" + path + "': out of memory");
  EGifSetGifVersion(gif, true);
  const int screen = EGifPutScreenDesc(gif, w, h, 8, 0, map);
  GifFreeMapObject(map);
  check(screen);
  // Loop for ever (the NETSCAPE2.0 application extension).
  static const GifByteType app[] = {'N', 'E', 'T', 'S', 'C', 'A', 'P', 'E', '2', '.', '0'};
  static const GifByteType loop[] = {1, 0, 0};
  check(EGifPutExtensionLeader(gif, APPLICATION_EXT_FUNC_CODE));
  check(EGifPutExtensionBlock(gif, sizeof app, app));
  check(EGifPutExtensionBlock(gif, sizeof loop, loop));
  check(EGifPutExtensionTrailer(gif));
  std::vector<GifPixelType> row(static_cast<std::size_t>(w));
  const auto at = [w](const IndexedFrame& f, int x, int y) {
    return f.index[static_cast<std::size_t>(y) * static_cast<std::size_t>(w) +
                   static_cast<std::size_t>(x)];
  };
  for (std::size_t k = 0; k < frames.size(); ++k) {
    const IndexedFrame& f = frames[k];
    // The rectangle that changed since the frame before (the whole frame first); a frame
    // equal to the one before is one pixel. DISPOSE_DO_NOT keeps the rest on screen.
    int x0 = 0, y0 = 0, x1 = w - 1, y1 = h - 1;
    if (k > 0) {
      const IndexedFrame& p = frames[k - 1];
      x0 = w, y0 = h, x1 = -1, y1 = -1;
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if (at(f, x, y) != at(p, x, y))
            x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
      if (x1 < 0) x0 = y0 = x1 = y1 = 0;
    }
    GraphicsControlBlock gcb{DISPOSE_DO_NOT, false,
                             k + 1 == frames.size() ? std::max(delay_cs, 150) : delay_cs,
                             NO_TRANSPARENT_COLOR};
    GifByteType ext[4];
    EGifGCBToExtension(&gcb, ext);
    check(EGifPutExtension(gif, GRAPHICS_EXT_FUNC_CODE, 4, ext));
    const int rw = x1 - x0 + 1, rh = y1 - y0 + 1;
    check(EGifPutImageDesc(gif, x0, y0, rw, rh, false, nullptr));
    for (int y = y0; y <= y1; ++y) {
      for (int x = x0; x <= x1; ++x) row[static_cast<std::size_t>(x - x0)] = at(f, x, y);
      check(EGifPutLine(gif, row.data(), rw));
    }
  }
  GifFileType* g = gif;
  gif = nullptr;
  if (EGifCloseFile(g, &err) == GIF_ERROR) fail(path, err);
}

}  // namespace hybgen::rt
