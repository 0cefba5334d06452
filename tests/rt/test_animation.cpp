// The animation (runtime/src/io/animation.cpp): the palette keeps the figures' colours
// close, and the GIF decodes (giflib's reader) to the frames written, each stored as the
// rectangle that changed, looping.

#include <gif_lib.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <vector>

#include "hybgen/rt/io/animation.hpp"
#include "hybgen/rt/io/colormap.hpp"

namespace {

namespace fs = std::filesystem;
using namespace hybgen::rt;

int channel_distance(std::uint32_t a, std::uint32_t b) {
  int d = 0;
  for (int s : {16, 8, 0})
    d = std::max(d, std::abs(static_cast<int>((a >> s) & 255) - static_cast<int>((b >> s) & 255)));
  return d;
}

TEST(Animation, ThePaletteKeepsTheFiguresColours) {
  EXPECT_EQ(gif_palette_colour(gif_palette_index(0xFFFFFF)), 0xFFFFFFu);  // the background
  EXPECT_EQ(gif_palette_colour(gif_palette_index(0x000000)), 0x000000u);
  for (int i = 0; i <= 20; ++i) {  // viridis, within a few levels per channel
    const auto c = viridis_rgb(i / 20.0);
    const std::uint32_t rgb = (std::uint32_t{c[0]} << 16) | (std::uint32_t{c[1]} << 8) | c[2];
    EXPECT_LE(channel_distance(gif_palette_colour(gif_palette_index(rgb)), rgb), 12) << i;
  }
  const std::uint32_t guard = 0xED542E;  // figures.cpp's guard colour
  EXPECT_LE(channel_distance(gif_palette_colour(gif_palette_index(guard)), guard), 6);
}

TEST(Animation, DecodesToTheFramesWritten) {
  // Three 40 x 30 frames: white, a dark square in frame 1, moved in frame 2.
  std::vector<IndexedFrame> frames;
  for (int k = 0; k < 3; ++k) {
    Raster r{40, 30, std::vector<std::uint32_t>(40 * 30, 0xFFFFFF)};
    if (k > 0)
      for (int y = 5; y < 15; ++y)
        for (int x = 5 + 10 * (k - 1); x < 15 + 10 * (k - 1); ++x)
          r.pixel[static_cast<std::size_t>(y * 40 + x)] = 0x440154;  // viridis(0)
    frames.push_back(quantize(r));
  }
  const fs::path p =
      fs::temp_directory_path() / ("hybgen_anim_" + std::to_string(::getpid()) + ".gif");
  write_gif(p.string(), frames, 10);
  int err = 0;
  GifFileType* g = DGifOpenFileName(p.c_str(), &err);
  ASSERT_NE(g, nullptr);
  ASSERT_EQ(DGifSlurp(g), GIF_OK);
  EXPECT_EQ(g->SWidth, 40);
  EXPECT_EQ(g->SHeight, 30);
  ASSERT_EQ(g->ImageCount, 3);
  // Frame 2 differs from frame 1 in x = 5..24, y = 5..14 only: that rectangle is stored.
  const GifImageDesc& d = g->SavedImages[2].ImageDesc;
  EXPECT_EQ(d.Left, 5);
  EXPECT_EQ(d.Top, 5);
  EXPECT_EQ(d.Width, 20);
  EXPECT_EQ(d.Height, 10);
  // Its pixels: the square's new place dark, its old place white again.
  const GifByteType* px = g->SavedImages[2].RasterBits;
  const ColorMapObject* map = g->SColorMap;
  const auto colour = [&](int x, int y) {
    const GifColorType c = map->Colors[px[(y - d.Top) * d.Width + (x - d.Left)]];
    return (std::uint32_t{c.Red} << 16) | (std::uint32_t{c.Green} << 8) | c.Blue;
  };
  EXPECT_LE(channel_distance(colour(20, 10), 0x440154), 12);
  EXPECT_EQ(colour(7, 10), 0xFFFFFFu);
  // Loops (NETSCAPE2.0) with the delay asked for.
  GraphicsControlBlock gcb;
  ASSERT_EQ(DGifSavedExtensionToGCB(g, 1, &gcb), GIF_OK);
  EXPECT_EQ(gcb.DelayTime, 10);
  DGifCloseFile(g, &err);
  fs::remove(p);
}

TEST(Animation, FramesOfDifferentSizesAreRefused) {
  std::vector<IndexedFrame> frames{quantize(Raster{2, 2, std::vector<std::uint32_t>(4)}),
                                   quantize(Raster{3, 2, std::vector<std::uint32_t>(6)})};
  EXPECT_THROW(write_gif("/tmp/never.gif", frames, 10), std::invalid_argument);
}

}  // namespace
