#pragma once
/// \file animation.hpp
/// An animated GIF of the frame figures (giflib): every frame of the run in one file that
/// any browser or slide plays, looping. The frames are the pictures of figures.hpp, reduced
/// to one 256-colour palette made for them: viridis (the heat maps), greys (text, axes,
/// anti-aliasing), and the guard, outside and not-a-number colours.

#include <cstdint>
#include <string>
#include <vector>

namespace hybgen::rt {

/// A picture as 0x00RRGGBB pixels, row-major from the top.
struct Raster {
  int width = 0;                     ///< Pixels per row.
  int height = 0;                    ///< Rows.
  std::vector<std::uint32_t> pixel;  ///< width × height.
};

/// A picture reduced to the animation's palette: one palette index per pixel.
struct IndexedFrame {
  int width = 0;                    ///< Pixels per row.
  int height = 0;                   ///< Rows.
  std::vector<std::uint8_t> index;  ///< width × height palette indices.
};

/// `r` in the palette's colours (each pixel its nearest entry); thread-safe.
IndexedFrame quantize(const Raster& r);

/// Writes `frames` (all of one size) to `path` as a looping GIF, `delay_cs` hundredths of a
/// second per frame; each frame after the first is stored as the rectangle where it differs
/// from the one before. Throws std::runtime_error naming the file.
void write_gif(const std::string& path, const std::vector<IndexedFrame>& frames, int delay_cs);

/// The palette's entry nearest to `rgb` (0x00RRGGBB); the palette, for tests.
std::uint8_t gif_palette_index(std::uint32_t rgb);
/// The palette's colour of entry `i` (0x00RRGGBB).
std::uint32_t gif_palette_colour(std::uint8_t i);

}  // namespace hybgen::rt
