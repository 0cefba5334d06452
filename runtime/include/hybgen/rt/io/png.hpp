#pragma once
/// \file png.hpp
/// PNG pictures of densities: a heat map with colour bar for 2-D grids and a line
/// plot for 1-D grids. Everything is drawn in memory (embedded 5x7 bitmap font with
/// descenders, drawn at 2x; embedded viridis table), encoded with libpng through an
/// in-memory writer and stored with the atomic writer.
///
/// Orientation: x axis horizontal, increasing to the right; y axis vertical,
/// increasing upward. Heat-map data are C-order arrays of shape (nx, ny), i.e. the
/// value at node (ix, iy) is `data[ix * ny + iy]` -- exactly the layout of a 2-D
/// state grid whose first state variable is x and whose last (fastest) is y.
///
/// libpng errors become std::runtime_error("libpng: <message>"); libpng is driven
/// from a single setjmp frame that holds no C++ objects, so the longjmp never
/// skips a destructor.
/// Size: the heat map and line plot, their colour maps and axes, the 5x7 bitmap font and
/// the PNG encoding through libpng, in one header the runner library compiles once.

#include <png.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "hybgen/rt/io/atomic_file.hpp"

namespace hybgen::rt {

/// An 8-bit sRGB colour.
struct Rgb {
  std::uint8_t r = 0;  ///< Red.
  std::uint8_t g = 0;  ///< Green.
  std::uint8_t b = 0;  ///< Blue.
  /// Component-wise equality.
  friend bool operator==(const Rgb&, const Rgb&) = default;
};

/// Where things ended up in a rendered plot, in pixels (origin top-left, y down).
struct PlotFrame {
  int width = 0;   ///< Image width.
  int height = 0;  ///< Image height.
  int plot_x = 0;  ///< Leftmost pixel column of the plot area.
  int plot_y = 0;  ///< Topmost pixel row of the plot area.
  int plot_w = 0;  ///< Plot-area width (data pixels, frame excluded).
  int plot_h = 0;  ///< Plot-area height (data pixels, frame excluded).
};

/// Colour drawn for NaN/inf heat-map nodes.
inline constexpr Rgb png_nonfinite_colour{255, 0, 255};
/// Colour drawn for heat-map nodes outside the state space.
inline constexpr Rgb png_outside_colour{214, 214, 214};

namespace detail {

/// Viridis (Smith & van der Walt, CC0; matplotlib's 256-entry table) as 8-bit sRGB.
inline constexpr std::array<std::array<std::uint8_t, 3>, 256> viridis_table{{
    {68, 1, 84},    {68, 2, 86},    {69, 4, 87},    {69, 5, 89},    {70, 7, 90},    {70, 8, 92},
    {70, 10, 93},   {70, 11, 94},   {71, 13, 96},   {71, 14, 97},   {71, 16, 99},   {71, 17, 100},
    {71, 19, 101},  {72, 20, 103},  {72, 22, 104},  {72, 23, 105},  {72, 24, 106},  {72, 26, 108},
    {72, 27, 109},  {72, 28, 110},  {72, 29, 111},  {72, 31, 112},  {72, 32, 113},  {72, 33, 115},
    {72, 35, 116},  {72, 36, 117},  {72, 37, 118},  {72, 38, 119},  {72, 40, 120},  {72, 41, 121},
    {71, 42, 122},  {71, 44, 122},  {71, 45, 123},  {71, 46, 124},  {71, 47, 125},  {70, 48, 126},
    {70, 50, 126},  {70, 51, 127},  {70, 52, 128},  {69, 53, 129},  {69, 55, 129},  {69, 56, 130},
    {68, 57, 131},  {68, 58, 131},  {68, 59, 132},  {67, 61, 132},  {67, 62, 133},  {66, 63, 133},
    {66, 64, 134},  {66, 65, 134},  {65, 66, 135},  {65, 68, 135},  {64, 69, 136},  {64, 70, 136},
    {63, 71, 136},  {63, 72, 137},  {62, 73, 137},  {62, 74, 137},  {62, 76, 138},  {61, 77, 138},
    {61, 78, 138},  {60, 79, 138},  {60, 80, 139},  {59, 81, 139},  {59, 82, 139},  {58, 83, 139},
    {58, 84, 140},  {57, 85, 140},  {57, 86, 140},  {56, 88, 140},  {56, 89, 140},  {55, 90, 140},
    {55, 91, 141},  {54, 92, 141},  {54, 93, 141},  {53, 94, 141},  {53, 95, 141},  {52, 96, 141},
    {52, 97, 141},  {51, 98, 141},  {51, 99, 141},  {50, 100, 142}, {50, 101, 142}, {49, 102, 142},
    {49, 103, 142}, {49, 104, 142}, {48, 105, 142}, {48, 106, 142}, {47, 107, 142}, {47, 108, 142},
    {46, 109, 142}, {46, 110, 142}, {46, 111, 142}, {45, 112, 142}, {45, 113, 142}, {44, 113, 142},
    {44, 114, 142}, {44, 115, 142}, {43, 116, 142}, {43, 117, 142}, {42, 118, 142}, {42, 119, 142},
    {42, 120, 142}, {41, 121, 142}, {41, 122, 142}, {41, 123, 142}, {40, 124, 142}, {40, 125, 142},
    {39, 126, 142}, {39, 127, 142}, {39, 128, 142}, {38, 129, 142}, {38, 130, 142}, {38, 130, 142},
    {37, 131, 142}, {37, 132, 142}, {37, 133, 142}, {36, 134, 142}, {36, 135, 142}, {35, 136, 142},
    {35, 137, 142}, {35, 138, 141}, {34, 139, 141}, {34, 140, 141}, {34, 141, 141}, {33, 142, 141},
    {33, 143, 141}, {33, 144, 141}, {33, 145, 140}, {32, 146, 140}, {32, 146, 140}, {32, 147, 140},
    {31, 148, 140}, {31, 149, 139}, {31, 150, 139}, {31, 151, 139}, {31, 152, 139}, {31, 153, 138},
    {31, 154, 138}, {30, 155, 138}, {30, 156, 137}, {30, 157, 137}, {31, 158, 137}, {31, 159, 136},
    {31, 160, 136}, {31, 161, 136}, {31, 161, 135}, {31, 162, 135}, {32, 163, 134}, {32, 164, 134},
    {33, 165, 133}, {33, 166, 133}, {34, 167, 133}, {34, 168, 132}, {35, 169, 131}, {36, 170, 131},
    {37, 171, 130}, {37, 172, 130}, {38, 173, 129}, {39, 173, 129}, {40, 174, 128}, {41, 175, 127},
    {42, 176, 127}, {44, 177, 126}, {45, 178, 125}, {46, 179, 124}, {47, 180, 124}, {49, 181, 123},
    {50, 182, 122}, {52, 182, 121}, {53, 183, 121}, {55, 184, 120}, {56, 185, 119}, {58, 186, 118},
    {59, 187, 117}, {61, 188, 116}, {63, 188, 115}, {64, 189, 114}, {66, 190, 113}, {68, 191, 112},
    {70, 192, 111}, {72, 193, 110}, {74, 193, 109}, {76, 194, 108}, {78, 195, 107}, {80, 196, 106},
    {82, 197, 105}, {84, 197, 104}, {86, 198, 103}, {88, 199, 101}, {90, 200, 100}, {92, 200, 99},
    {94, 201, 98},  {96, 202, 96},  {99, 203, 95},  {101, 203, 94}, {103, 204, 92}, {105, 205, 91},
    {108, 205, 90}, {110, 206, 88}, {112, 207, 87}, {115, 208, 86}, {117, 208, 84}, {119, 209, 83},
    {122, 209, 81}, {124, 210, 80}, {127, 211, 78}, {129, 211, 77}, {132, 212, 75}, {134, 213, 73},
    {137, 213, 72}, {139, 214, 70}, {142, 214, 69}, {144, 215, 67}, {147, 215, 65}, {149, 216, 64},
    {152, 216, 62}, {155, 217, 60}, {157, 217, 59}, {160, 218, 57}, {162, 218, 55}, {165, 219, 54},
    {168, 219, 52}, {170, 220, 50}, {173, 220, 48}, {176, 221, 47}, {178, 221, 45}, {181, 222, 43},
    {184, 222, 41}, {186, 222, 40}, {189, 223, 38}, {192, 223, 37}, {194, 223, 35}, {197, 224, 33},
    {200, 224, 32}, {202, 225, 31}, {205, 225, 29}, {208, 225, 28}, {210, 226, 27}, {213, 226, 26},
    {216, 226, 25}, {218, 227, 25}, {221, 227, 24}, {223, 227, 24}, {226, 228, 24}, {229, 228, 25},
    {231, 228, 25}, {234, 229, 26}, {236, 229, 27}, {239, 229, 28}, {241, 229, 29}, {244, 230, 30},
    {246, 230, 32}, {248, 230, 33}, {251, 231, 35}, {253, 231, 37},
}};

/// 5-column bitmap glyphs for ASCII 32..126, 9 rows each (bit 4 = leftmost column).
/// Rows 0-6 hold capitals and digits (cap height 7, baseline below row 6); rows 7-8
/// hold descenders (g j p q y , _).
inline constexpr std::array<std::array<std::uint8_t, 9>, 95> font_glyphs{{
    {{0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},  // space
    {{0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x04, 0x00, 0x00}},  // !
    {{0x0A, 0x0A, 0x0A, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},  // "
    {{0x0A, 0x0A, 0x1F, 0x0A, 0x1F, 0x0A, 0x0A, 0x00, 0x00}},  // #
    {{0x04, 0x0F, 0x14, 0x0E, 0x05, 0x1E, 0x04, 0x00, 0x00}},  // $
    {{0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03, 0x00, 0x00}},  // %
    {{0x0C, 0x12, 0x14, 0x08, 0x15, 0x12, 0x0D, 0x00, 0x00}},  // &
    {{0x04, 0x04, 0x08, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},  // quote
    {{0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02, 0x00, 0x00}},  // (
    {{0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08, 0x00, 0x00}},  // )
    {{0x00, 0x04, 0x15, 0x0E, 0x15, 0x04, 0x00, 0x00, 0x00}},  // *
    {{0x00, 0x04, 0x04, 0x1F, 0x04, 0x04, 0x00, 0x00, 0x00}},  // +
    {{0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x04, 0x08, 0x00}},  // ,
    {{0x00, 0x00, 0x00, 0x1F, 0x00, 0x00, 0x00, 0x00, 0x00}},  // -
    {{0x00, 0x00, 0x00, 0x00, 0x00, 0x0C, 0x0C, 0x00, 0x00}},  // .
    {{0x00, 0x01, 0x02, 0x04, 0x08, 0x10, 0x00, 0x00, 0x00}},  // /
    {{0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E, 0x00, 0x00}},  // 0
    {{0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E, 0x00, 0x00}},  // 1
    {{0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F, 0x00, 0x00}},  // 2
    {{0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E, 0x00, 0x00}},  // 3
    {{0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02, 0x00, 0x00}},  // 4
    {{0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E, 0x00, 0x00}},  // 5
    {{0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E, 0x00, 0x00}},  // 6
    {{0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08, 0x00, 0x00}},  // 7
    {{0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E, 0x00, 0x00}},  // 8
    {{0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C, 0x00, 0x00}},  // 9
    {{0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x0C, 0x00, 0x00, 0x00}},  // :
    {{0x00, 0x0C, 0x0C, 0x00, 0x0C, 0x04, 0x08, 0x00, 0x00}},  // ;
    {{0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02, 0x00, 0x00}},  // <
    {{0x00, 0x00, 0x1F, 0x00, 0x1F, 0x00, 0x00, 0x00, 0x00}},  // =
    {{0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08, 0x00, 0x00}},  // >
    {{0x0E, 0x11, 0x01, 0x02, 0x04, 0x00, 0x04, 0x00, 0x00}},  // ?
    {{0x0E, 0x11, 0x01, 0x0D, 0x15, 0x15, 0x0E, 0x00, 0x00}},  // @
    {{0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11, 0x00, 0x00}},  // A
    {{0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E, 0x00, 0x00}},  // B
    {{0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E, 0x00, 0x00}},  // C
    {{0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C, 0x00, 0x00}},  // D
    {{0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F, 0x00, 0x00}},  // E
    {{0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10, 0x00, 0x00}},  // F
    {{0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F, 0x00, 0x00}},  // G
    {{0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11, 0x00, 0x00}},  // H
    {{0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E, 0x00, 0x00}},  // I
    {{0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C, 0x00, 0x00}},  // J
    {{0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11, 0x00, 0x00}},  // K
    {{0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F, 0x00, 0x00}},  // L
    {{0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11, 0x00, 0x00}},  // M
    {{0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11, 0x00, 0x00}},  // N
    {{0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E, 0x00, 0x00}},  // O
    {{0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10, 0x00, 0x00}},  // P
    {{0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D, 0x00, 0x00}},  // Q
    {{0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11, 0x00, 0x00}},  // R
    {{0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E, 0x00, 0x00}},  // S
    {{0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x00}},  // T
    {{0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E, 0x00, 0x00}},  // U
    {{0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04, 0x00, 0x00}},  // V
    {{0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A, 0x00, 0x00}},  // W
    {{0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11, 0x00, 0x00}},  // X
    {{0x11, 0x11, 0x0A, 0x04, 0x04, 0x04, 0x04, 0x00, 0x00}},  // Y
    {{0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F, 0x00, 0x00}},  // Z
    {{0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E, 0x00, 0x00}},  // [
    {{0x00, 0x10, 0x08, 0x04, 0x02, 0x01, 0x00, 0x00, 0x00}},  // backslash
    {{0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E, 0x00, 0x00}},  // ]
    {{0x04, 0x0A, 0x11, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},  // ^
    {{0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00, 0x1F, 0x00}},  // _
    {{0x08, 0x04, 0x02, 0x00, 0x00, 0x00, 0x00, 0x00, 0x00}},  // `
    {{0x00, 0x00, 0x0E, 0x01, 0x0F, 0x11, 0x0F, 0x00, 0x00}},  // a
    {{0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x1E, 0x00, 0x00}},  // b
    {{0x00, 0x00, 0x0E, 0x10, 0x10, 0x11, 0x0E, 0x00, 0x00}},  // c
    {{0x01, 0x01, 0x0D, 0x13, 0x11, 0x11, 0x0F, 0x00, 0x00}},  // d
    {{0x00, 0x00, 0x0E, 0x11, 0x1F, 0x10, 0x0E, 0x00, 0x00}},  // e
    {{0x06, 0x09, 0x08, 0x1C, 0x08, 0x08, 0x08, 0x00, 0x00}},  // f
    {{0x00, 0x00, 0x0F, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E}},  // g
    {{0x10, 0x10, 0x16, 0x19, 0x11, 0x11, 0x11, 0x00, 0x00}},  // h
    {{0x04, 0x00, 0x0C, 0x04, 0x04, 0x04, 0x0E, 0x00, 0x00}},  // i
    {{0x02, 0x00, 0x06, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C}},  // j
    {{0x10, 0x10, 0x12, 0x14, 0x18, 0x14, 0x12, 0x00, 0x00}},  // k
    {{0x0C, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E, 0x00, 0x00}},  // l
    {{0x00, 0x00, 0x1A, 0x15, 0x15, 0x15, 0x15, 0x00, 0x00}},  // m
    {{0x00, 0x00, 0x16, 0x19, 0x11, 0x11, 0x11, 0x00, 0x00}},  // n
    {{0x00, 0x00, 0x0E, 0x11, 0x11, 0x11, 0x0E, 0x00, 0x00}},  // o
    {{0x00, 0x00, 0x1E, 0x11, 0x11, 0x11, 0x1E, 0x10, 0x10}},  // p
    {{0x00, 0x00, 0x0F, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x01}},  // q
    {{0x00, 0x00, 0x16, 0x19, 0x10, 0x10, 0x10, 0x00, 0x00}},  // r
    {{0x00, 0x00, 0x0F, 0x10, 0x0E, 0x01, 0x1E, 0x00, 0x00}},  // s
    {{0x08, 0x08, 0x1C, 0x08, 0x08, 0x09, 0x06, 0x00, 0x00}},  // t
    {{0x00, 0x00, 0x11, 0x11, 0x11, 0x13, 0x0D, 0x00, 0x00}},  // u
    {{0x00, 0x00, 0x11, 0x11, 0x11, 0x0A, 0x04, 0x00, 0x00}},  // v
    {{0x00, 0x00, 0x11, 0x11, 0x15, 0x15, 0x0A, 0x00, 0x00}},  // w
    {{0x00, 0x00, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x00, 0x00}},  // x
    {{0x00, 0x00, 0x11, 0x11, 0x11, 0x11, 0x0F, 0x01, 0x0E}},  // y
    {{0x00, 0x00, 0x1F, 0x02, 0x04, 0x08, 0x1F, 0x00, 0x00}},  // z
    {{0x02, 0x04, 0x04, 0x08, 0x04, 0x04, 0x02, 0x00, 0x00}},  // {
    {{0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04, 0x00, 0x00}},  // |
    {{0x08, 0x04, 0x04, 0x02, 0x04, 0x04, 0x08, 0x00, 0x00}},  // }
    {{0x00, 0x00, 0x08, 0x15, 0x02, 0x00, 0x00, 0x00, 0x00}},  // ~
}};

inline constexpr int font_cols = 5;        ///< Glyph width in font pixels.
inline constexpr int font_rows = 9;        ///< Glyph height incl. descender rows.
inline constexpr int font_advance = 6;     ///< Horizontal advance per character.
inline constexpr int font_cap_height = 7;  ///< Height of capitals and digits.

inline constexpr Rgb white{255, 255, 255};     ///< Background.
inline constexpr Rgb ink{30, 30, 30};          ///< Text.
inline constexpr Rgb axis_ink{70, 70, 70};     ///< Frames and tick marks.
inline constexpr Rgb grid_ink{232, 232, 232};  ///< Line-plot grid lines.
inline constexpr Rgb line_ink{49, 104, 142};   ///< Line-plot curve (viridis 0.3).

/// An RGB raster with clipped drawing primitives.
class Canvas {
 public:
  /// A `width` x `height` canvas filled with `background`.
  Canvas(int width, int height, Rgb background)
      : width_(std::max(width, 0)),
        height_(std::max(height, 0)),
        pixels_(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_) * 3) {
    fill_rect(0, 0, width_, height_, background);
  }
  /// Width in pixels.
  int width() const { return width_; }
  /// Height in pixels.
  int height() const { return height_; }
  /// Whether (x, y) lies on the canvas.
  bool contains(int x, int y) const { return x >= 0 && y >= 0 && x < width_ && y < height_; }
  /// Sets one pixel (ignored off-canvas).
  void set(int x, int y, Rgb c) {
    if (!contains(x, y)) return;
    std::uint8_t* p = &pixels_[index(x, y)];
    p[0] = c.r;
    p[1] = c.g;
    p[2] = c.b;
  }
  /// Reads one pixel (white off-canvas).
  Rgb get(int x, int y) const {
    if (!contains(x, y)) return white;
    const std::uint8_t* p = &pixels_[index(x, y)];
    return {p[0], p[1], p[2]};
  }
  /// Mixes `c` into pixel (x, y) with opacity `alpha` in [0, 1].
  void blend(int x, int y, Rgb c, double alpha) {
    if (!contains(x, y) || !(alpha > 0.0)) return;
    alpha = std::min(alpha, 1.0);
    const Rgb o = get(x, y);
    const auto mix = [alpha](std::uint8_t from, std::uint8_t to) {
      return static_cast<std::uint8_t>(std::lround(from + (to - from) * alpha));
    };
    set(x, y, {mix(o.r, c.r), mix(o.g, c.g), mix(o.b, c.b)});
  }
  /// Fills the rectangle [x, x+w) x [y, y+h), clipped.
  void fill_rect(int x, int y, int w, int h, Rgb c) {
    const int x0 = std::max(x, 0), x1 = std::min(x + w, width_);
    const int y0 = std::max(y, 0), y1 = std::min(y + h, height_);
    for (int yy = y0; yy < y1; ++yy)
      for (int xx = x0; xx < x1; ++xx) set(xx, yy, c);
  }
  /// Draws the 1-pixel outline of the rectangle [x, x+w) x [y, y+h).
  void outline_rect(int x, int y, int w, int h, Rgb c) {
    fill_rect(x, y, w, 1, c);
    fill_rect(x, y + h - 1, w, 1, c);
    fill_rect(x, y, 1, h, c);
    fill_rect(x + w - 1, y, 1, h, c);
  }
  /// First byte of row `y` (RGB triples, `width()` of them).
  const std::uint8_t* row(int y) const { return pixels_.data() + index(0, y); }

 private:
  std::size_t index(int x, int y) const {
    return (static_cast<std::size_t>(y) * static_cast<std::size_t>(width_) +
            static_cast<std::size_t>(x)) *
           3;
  }

  int width_;
  int height_;
  std::vector<std::uint8_t> pixels_;
};

/// One glyph per character: printable ASCII is kept, each other byte or UTF-8 sequence
/// becomes '?', and control characters become spaces.
inline std::string sanitize_text(std::string_view s) {
  std::string out;
  out.reserve(s.size());
  for (const char ch : s) {
    const auto u = static_cast<unsigned char>(ch);
    if (u >= 0x80 && u < 0xC0) continue;  // UTF-8 continuation byte
    if (u >= 0x80) {
      out += '?';
    } else if (u < 0x20 || u == 0x7F) {
      out += ' ';
    } else {
      out += ch;
    }
  }
  return out;
}

/// Width in pixels of sanitized text `s` at `scale`.
inline int text_width(std::string_view s, int scale) {
  if (s.empty()) return 0;
  return (static_cast<int>(s.size()) * font_advance - 1) * scale;
}

/// Cuts sanitized text `s` to at most `max_width` pixels, ending it in "..." when cut.
inline std::string fit_text(std::string s, int max_width, int scale) {
  if (text_width(s, scale) <= max_width) return s;
  while (!s.empty() && text_width(s + "...", scale) > max_width) s.pop_back();
  return s.empty() ? std::string() : s + "...";
}

/// The glyph rows for character `c` ('?' outside 32..126).
inline const std::array<std::uint8_t, 9>& glyph(char c) {
  auto u = static_cast<unsigned char>(c);
  if (u < 32 || u > 126) u = '?';
  return font_glyphs[static_cast<std::size_t>(u - 32)];
}

/// Draws sanitized text with its top-left corner (cap line) at (x, y); `bold` doubles
/// the strokes horizontally.
inline void draw_text(Canvas& cv, int x, int y, std::string_view s, int scale, Rgb c,
                      bool bold = false) {
  for (const char ch : s) {
    const auto& g = glyph(ch);
    for (int r = 0; r < font_rows; ++r)
      for (int col = 0; col < font_cols; ++col)
        if ((g[static_cast<std::size_t>(r)] >> (font_cols - 1 - col)) & 1u)
          cv.fill_rect(x + col * scale, y + r * scale, scale + (bold ? 1 : 0), scale, c);
    x += font_advance * scale;
  }
}

/// Draws sanitized text rotated 90 degrees counter-clockwise (reading upward): the
/// glyph tops face left at column `x`, and the text starts at row `y_bottom`.
inline void draw_text_up(Canvas& cv, int x, int y_bottom, std::string_view s, int scale, Rgb c) {
  int along = 0;
  for (const char ch : s) {
    const auto& g = glyph(ch);
    for (int r = 0; r < font_rows; ++r)
      for (int col = 0; col < font_cols; ++col)
        if ((g[static_cast<std::size_t>(r)] >> (font_cols - 1 - col)) & 1u)
          cv.fill_rect(x + r * scale, y_bottom - (along + col + 1) * scale, scale, scale, c);
    along += font_advance;
  }
}

/// "1.5e-05" -> "1.5e-5", "2e+06" -> "2e6"; other strings unchanged.
inline std::string compact_exponent(const std::string& s) {
  const std::size_t e = s.find('e');
  if (e == std::string::npos) return s;
  std::string exp = s.substr(e + 1);
  const bool neg = !exp.empty() && exp[0] == '-';
  if (!exp.empty() && (exp[0] == '-' || exp[0] == '+')) exp.erase(0, 1);
  while (exp.size() > 1 && exp[0] == '0') exp.erase(0, 1);
  return s.substr(0, e) + "e" + (neg ? "-" : "") + exp;
}

/// A bounded snprintf result as std::string.
inline std::string from_buffer(const char* buf, int n, std::size_t cap) {
  return std::string(buf, std::min(static_cast<std::size_t>(std::max(n, 0)), cap - 1));
}

/// `v` in fixed notation with `decimals` digits after the point.
inline std::string format_fixed(double v, int decimals) {
  char buf[64];
  return from_buffer(buf, std::snprintf(buf, sizeof buf, "%.*f", decimals, v), sizeof buf);
}

/// `v` in compact scientific notation with at most `decimals` mantissa digits and no
/// trailing zeros: "2.5e-5", "1e-4".
inline std::string format_scientific(double v, int decimals) {
  char buf[64];
  std::string s = from_buffer(buf, std::snprintf(buf, sizeof buf, "%.*e", decimals, v), sizeof buf);
  const std::size_t e = s.find('e');
  if (e != std::string::npos && s.find('.') < e) {
    std::size_t end = e;
    while (s[end - 1] == '0') --end;
    if (s[end - 1] == '.') --end;
    s.erase(end, e - end);
  }
  return compact_exponent(s);
}

/// A data value with three significant digits: "0.0123", "1.23e-5", "-4.5".
inline std::string format_value(double v) {
  if (v == 0.0) return "0";
  if (std::isnan(v)) return "NaN";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  return compact_exponent(from_buffer(buf, std::snprintf(buf, sizeof buf, "%.3g", v), sizeof buf));
}

/// Tick positions on one axis and their labels.
struct Ticks {
  double step = 1.0;                ///< Distance between ticks.
  std::vector<double> values;       ///< Tick values, increasing.
  std::vector<std::string> labels;  ///< One label per value.
};

/// The smallest 1-2-5 x 10^k step that is >= `raw`.
inline double nice_step_at_least(double raw) {
  const double base = std::pow(10.0, std::floor(std::log10(raw)));
  for (const double m : {1.0, 2.0, 5.0, 10.0})
    if (m * base >= raw * (1.0 - 1e-9)) return m * base;
  return 10.0 * base;
}

/// Ticks at the multiples of `step` in [lo, hi], labelled with a precision that
/// suits `step` (fixed notation for moderate magnitudes, else compact scientific).
inline Ticks make_ticks(double lo, double hi, double step) {
  Ticks t;
  t.step = step;
  const double k0 = std::ceil(lo / step - 1e-9), k1 = std::floor(hi / step + 1e-9);
  for (double k = k0; k <= k1 && t.values.size() < 64; k += 1.0) {
    const double v = k * step;
    t.values.push_back(std::fabs(v) < step * 1e-9 ? 0.0 : v);
  }
  double max_abs = 0.0;
  for (const double v : t.values) max_abs = std::max(max_abs, std::fabs(v));
  const int e = static_cast<int>(std::floor(std::log10(step) + 1e-9));
  const bool fixed = step >= 1e-3 && max_abs < 1e5;
  for (const double v : t.values) {
    if (fixed) {
      t.labels.push_back(format_fixed(v, std::max(0, -e)));
    } else if (v == 0.0) {
      t.labels.emplace_back("0");
    } else {
      const int ev = static_cast<int>(std::floor(std::log10(std::fabs(v)) + 1e-9));
      t.labels.push_back(format_scientific(v, std::max(0, ev - e)));
    }
  }
  return t;
}

/// Ticks for [lo, hi] drawn over `length` pixels: the densest 1-2-5 grid with at most
/// `max_ticks` ticks whose labels keep `min_gap` pixels apart, where a label occupies
/// its text width (`horizontal`) or the cap height (vertical axis) at `scale`.
inline Ticks choose_ticks(double lo, double hi, int length, int max_ticks, bool horizontal,
                          int scale, int min_gap) {
  const double span = hi - lo;
  double step = nice_step_at_least(span / (4.0 * max_ticks));  // too fine; coarsen below
  Ticks t;
  for (int attempt = 0; attempt < 40; ++attempt) {
    t = make_ticks(lo, hi, step);
    int extent = font_cap_height * scale;
    if (horizontal)
      for (const auto& l : t.labels) extent = std::max(extent, text_width(l, scale));
    const double px_per_step = step / span * length;
    const bool few_enough = t.values.size() <= static_cast<std::size_t>(max_ticks);
    if (t.values.size() <= 1 || (few_enough && px_per_step >= extent + min_gap)) break;
    step = nice_step_at_least(step * 1.000001);
  }
  return t;
}

/// Pixel offset in [0, length) of value v on an axis spanning [lo, hi] over `length`.
inline int axis_pixel(double v, double lo, double hi, int length) {
  const double p = (v - lo) / (hi - lo) * length;
  return std::clamp(static_cast<int>(std::floor(p)), 0, length - 1);
}

/// Accumulates anti-aliased coverage of strokes over a clip rectangle, then paints it
/// once, so overlapping segments of one polyline do not darken their joints.
class CoverageMask {
 public:
  /// A mask over [x0, x0+w) x [y0, y0+h).
  CoverageMask(int x0, int y0, int w, int h)
      : x0_(x0),
        y0_(y0),
        w_(w),
        h_(h),
        cov_(static_cast<std::size_t>(std::max(w, 0)) * static_cast<std::size_t>(std::max(h, 0)),
             0.0) {}
  /// Adds a segment from (ax, ay) to (bx, by) (pixel coordinates) of width `lw`.
  void segment(double ax, double ay, double bx, double by, double lw) {
    const double r = lw / 2.0 + 0.5;
    const int px0 = static_cast<int>(std::floor(std::min(ax, bx) - r)) - 1;
    const int px1 = static_cast<int>(std::ceil(std::max(ax, bx) + r)) + 1;
    const int py0 = static_cast<int>(std::floor(std::min(ay, by) - r)) - 1;
    const int py1 = static_cast<int>(std::ceil(std::max(ay, by) + r)) + 1;
    const double dx = bx - ax, dy = by - ay, len2 = dx * dx + dy * dy;
    for (int py = std::max(py0, y0_); py <= std::min(py1, y0_ + h_ - 1); ++py) {
      for (int px = std::max(px0, x0_); px <= std::min(px1, x0_ + w_ - 1); ++px) {
        const double cx = px + 0.5, cy = py + 0.5;
        double s = len2 > 0.0 ? ((cx - ax) * dx + (cy - ay) * dy) / len2 : 0.0;
        s = std::clamp(s, 0.0, 1.0);
        const double ex = cx - (ax + s * dx), ey = cy - (ay + s * dy);
        add(px, py, lw / 2.0 + 0.5 - std::sqrt(ex * ex + ey * ey));
      }
    }
  }
  /// Adds a filled disc of radius `rad` centred at (cx, cy).
  void disc(double cx, double cy, double rad) { segment(cx, cy, cx, cy, 2.0 * rad); }
  /// Blends colour `c` into `cv` with the accumulated coverage.
  void paint(Canvas& cv, Rgb c) const {
    for (int y = 0; y < h_; ++y)
      for (int x = 0; x < w_; ++x) cv.blend(x0_ + x, y0_ + y, c, cov_[at(x0_ + x, y0_ + y)]);
  }

 private:
  std::size_t at(int px, int py) const {
    return static_cast<std::size_t>(py - y0_) * static_cast<std::size_t>(w_) +
           static_cast<std::size_t>(px - x0_);
  }
  void add(int px, int py, double coverage) {
    double& v = cov_[at(px, py)];
    v = std::max(v, std::clamp(coverage, 0.0, 1.0));
  }

  int x0_, y0_, w_, h_;
  std::vector<double> cov_;
};

/// Error state shared with the libpng callbacks (plain data: it crosses longjmp).
struct PngErrorState {
  char message[256];  ///< The last libpng error message.
};

/// libpng error callback: records the message and longjmps back to `png_encode_raw`.
inline void png_error_handler(png_structp png, png_const_charp msg) {
  auto* st = static_cast<PngErrorState*>(png_get_error_ptr(png));
  std::snprintf(st->message, sizeof st->message, "%s", msg != nullptr ? msg : "unknown error");
  png_longjmp(png, 1);
}

/// libpng warning callback: warnings are not errors; ignore them.
inline void png_warning_handler(png_structp, png_const_charp) {}

/// libpng write callback: appends to the std::vector<std::uint8_t> behind the io pointer.
inline void png_write_to_vector(png_structp png, png_bytep data, std::size_t len) {
  auto* out = static_cast<std::vector<std::uint8_t>*>(png_get_io_ptr(png));
  bool ok = true;
  try {
    out->insert(out->end(), data, data + len);
  } catch (...) {
    ok = false;
  }
  if (!ok) png_error(png, "out of memory while encoding");
}

/// libpng flush callback: nothing to flush in memory.
inline void png_flush_noop(png_structp) {}

/// The only function that calls setjmp. It holds no C++ objects and modifies no locals,
/// so a longjmp from libpng skips no destructor and clobbers nothing. Returns false if
/// libpng reported an error (message in the error state).
[[gnu::noinline]] inline bool png_encode_raw(png_structp png, png_infop info, png_bytepp rows,
                                             png_uint_32 width, png_uint_32 height, png_textp text,
                                             int n_text) {
  if (setjmp(png_jmpbuf(png))) return false;
  png_set_IHDR(png, info, width, height, 8, PNG_COLOR_TYPE_RGB, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_text(png, info, text, n_text);
  png_write_info(png, info);
  png_write_image(png, rows);
  png_write_end(png, nullptr);
  return true;
}

/// Encodes `cv` as an 8-bit RGB PNG in memory with tEXt Title/Software chunks.
/// Throws std::runtime_error("libpng: ...") when libpng fails (e.g. a zero-size image).
inline std::vector<std::uint8_t> encode_png(const Canvas& cv, const std::string& title) {
  std::vector<std::uint8_t> out;
  std::vector<png_bytep> rows(static_cast<std::size_t>(cv.height()));
  for (int y = 0; y < cv.height(); ++y)
    rows[static_cast<std::size_t>(y)] = const_cast<png_bytep>(cv.row(y));  // libpng only reads
  std::string title_text = sanitize_text(title), software = "hybgen";
  char key_title[] = "Title", key_software[] = "Software";
  std::array<png_text, 2> text{};
  text[0].compression = PNG_TEXT_COMPRESSION_NONE;
  text[0].key = key_title;
  text[0].text = title_text.data();
  text[0].text_length = title_text.size();
  text[1].compression = PNG_TEXT_COMPRESSION_NONE;
  text[1].key = key_software;
  text[1].text = software.data();
  text[1].text_length = software.size();
  const int n_text = title_text.empty() ? 1 : 2;
  png_textp first_text = title_text.empty() ? &text[1] : &text[0];

  PngErrorState state{};
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &state, png_error_handler,
                                            png_warning_handler);
  if (png == nullptr) throw std::runtime_error("libpng: cannot create write struct");
  png_infop info = png_create_info_struct(png);
  if (info == nullptr) {
    png_destroy_write_struct(&png, nullptr);
    throw std::runtime_error("libpng: cannot create info struct");
  }
  png_set_write_fn(png, &out, png_write_to_vector, png_flush_noop);
  const bool ok = png_encode_raw(png, info, rows.data(), static_cast<png_uint_32>(cv.width()),
                                 static_cast<png_uint_32>(cv.height()), first_text, n_text);
  png_destroy_write_struct(&png, &info);
  if (!ok) throw std::runtime_error(std::string("libpng: ") + state.message);
  return out;
}

/// Encodes `cv` and stores it at `path` atomically.
inline void save_png(const std::string& path, const Canvas& cv, const std::string& title) {
  const std::vector<std::uint8_t> bytes = encode_png(cv, title);
  write_file_atomic(path, bytes.data(), bytes.size());
}

/// Layout constants shared by both plot kinds (pixels; text at `text_scale`).
inline constexpr int text_scale = 2;                         ///< Font scale of all text.
inline constexpr int text_h = font_cap_height * text_scale;  ///< Cap height of text.
inline constexpr int margin = 14;                            ///< Outer padding.
inline constexpr int tick_len = 5;                           ///< Tick-mark length.
inline constexpr int tick_gap = 5;                           ///< Tick mark to label.
inline constexpr int title_top = 16;                         ///< Top of the title.
inline constexpr int plot_top = 54;                          ///< Top of the plot area.
inline constexpr int axis_name_gap = 12;                     ///< Tick labels to axis name.
inline constexpr int bottom_margin = tick_len + tick_gap + text_h + axis_name_gap + text_h +
                                     2 * text_scale + margin;  ///< Below the plot area.

/// Draws the frame, tick marks and labels, axis names and title around plot area `f`;
/// `y_label_w` is the width reserved for the y tick labels.
inline void draw_axes(Canvas& cv, const PlotFrame& f, const Ticks& xt, double x_lo, double x_hi,
                      const Ticks& yt, double y_lo, double y_hi, const std::string& x_name,
                      const std::string& y_name, const std::string& title, int y_label_w) {
  const int px0 = f.plot_x, py0 = f.plot_y, pw = f.plot_w, ph = f.plot_h;
  cv.outline_rect(px0 - 1, py0 - 1, pw + 2, ph + 2, axis_ink);
  const int label_top = py0 + ph + 1 + tick_len + tick_gap;
  for (std::size_t i = 0; i < xt.values.size(); ++i) {
    const int x = px0 + axis_pixel(xt.values[i], x_lo, x_hi, pw);
    cv.fill_rect(x, py0 + ph + 1, 1, tick_len, axis_ink);
    const int w = text_width(xt.labels[i], text_scale);
    draw_text(cv, x - w / 2, label_top, xt.labels[i], text_scale, ink);
  }
  for (std::size_t i = 0; i < yt.values.size(); ++i) {
    const int y = py0 + ph - 1 - axis_pixel(yt.values[i], y_lo, y_hi, ph);
    cv.fill_rect(px0 - 1 - tick_len, y, tick_len, 1, axis_ink);
    const int w = text_width(yt.labels[i], text_scale);
    draw_text(cv, px0 - 1 - tick_len - tick_gap - w, y - text_h / 2, yt.labels[i], text_scale, ink);
  }
  const std::string xn = fit_text(sanitize_text(x_name), pw, text_scale);
  draw_text(cv, px0 + (pw - text_width(xn, text_scale)) / 2, label_top + text_h + axis_name_gap, xn,
            text_scale, ink);
  const std::string yn = fit_text(sanitize_text(y_name), ph, text_scale);
  const int yn_x = px0 - 1 - tick_len - tick_gap - y_label_w - axis_name_gap - text_h;
  draw_text_up(cv, yn_x, py0 + (ph + text_width(yn, text_scale)) / 2, yn, text_scale, ink);
  const std::string tt = fit_text(sanitize_text(title), cv.width() - 2 * margin, text_scale);
  const int tw = text_width(tt, text_scale) + 1;  // bold adds a column
  int tx = px0 + (pw - tw) / 2;
  tx = std::clamp(tx, margin, std::max(margin, cv.width() - margin - tw));
  draw_text(cv, tx, title_top, tt, text_scale, ink, true);
}

/// Widest label of `t` at the text scale.
inline int widest_label(const Ticks& t) {
  int w = 0;
  for (const auto& l : t.labels) w = std::max(w, text_width(l, text_scale));
  return w;
}

/// Left margin that fits the rotated y-axis name, `y_label_w` pixels of y tick labels
/// and the tick marks.
inline int left_margin(int y_label_w) {
  return margin + text_h + axis_name_gap + y_label_w + tick_gap + tick_len + 1;
}

/// Axis extent [lo, hi] covered by `n` nodes from `first` to `last`, each painted as
/// a cell centred on its node.
inline std::pair<double, double> node_axis_extent(std::size_t n, double first, double last) {
  if (n > 1) {
    const double half = (last - first) / static_cast<double>(n - 1) / 2.0;
    return {first - half, last + half};
  }
  const double c = (first + last) / 2.0;
  double half = (last - first) / 2.0;
  if (!(half > 0.0)) half = first != 0.0 ? std::fabs(first) * 0.5 : 0.5;
  return {c - half, c + half};
}

/// Throws std::invalid_argument unless [first, last] is a usable node range for n nodes.
inline void check_node_range(const char* axis, std::size_t n, double first, double last) {
  if (n == 0) throw std::invalid_argument(std::string("heat map: ") + axis + " has no nodes");
  if (!std::isfinite(first) || !std::isfinite(last) || (n > 1 && !(last > first)) ||
      (n == 1 && last < first))
    throw std::invalid_argument(std::string("heat map: invalid ") + axis + " range");
}

}  // namespace detail

/// Viridis colour for t in [0, 1] (clamped; NaN maps to the low end).
inline Rgb viridis(double t) {
  if (!(t > 0.0)) t = 0.0;
  const auto i = static_cast<std::size_t>(std::min(t * 256.0, 255.0));
  const auto& e = detail::viridis_table[i];
  return {e[0], e[1], e[2]};
}

/// Renders a heat map of a 2-D node grid to an RGB PNG at `path` (written atomically).
///
/// Data layout: `data[ix * ny + iy]` is the value at node (ix, iy), i.e. a C-order
/// (nx, ny) array; node ix sits at x_min + ix (x_max - x_min)/(nx - 1) on the
/// horizontal axis (increasing to the right), node iy at y_min + iy (y_max -
/// y_min)/(ny - 1) on the vertical axis (increasing upward). Each node is painted
/// (nearest neighbour) as the cell centred on it, so the axes extend half a cell
/// beyond [x_min, x_max] and [y_min, y_max]. `outside`, when not null, has the same
/// layout; a nonzero entry marks a node outside the state space (drawn light grey).
/// NaN/inf values are drawn magenta and excluded from the colour range. Colours are
/// viridis over [min, max] of the remaining values; a constant field maps to the
/// middle of a range widened around it. The plot area is 480 x 480 pixels; the image
/// is about 750 x 600 with a title, tick labels at 1-2-5 steps, axis names, and a
/// colour bar labelled with the data minimum and maximum. Returns the geometry.
/// Throws std::invalid_argument for bad arguments, std::runtime_error for I/O and
/// libpng errors.
inline PlotFrame write_heatmap_png(const std::string& path, const double* data, std::size_t nx,
                                   std::size_t ny, const std::string& x_name, double x_min,
                                   double x_max, const std::string& y_name, double y_min,
                                   double y_max, const std::string& title,
                                   const std::uint8_t* outside = nullptr) {
  using namespace detail;
  if (data == nullptr) throw std::invalid_argument("heat map: null data for " + path);
  check_node_range("x", nx, x_min, x_max);
  check_node_range("y", ny, y_min, y_max);
  if (nx > std::numeric_limits<std::size_t>::max() / ny)
    throw std::invalid_argument("heat map: grid too large");
  const std::size_t n = nx * ny;

  // Colour range over finite nodes inside the state space.
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  bool any_nonfinite = false, any_outside = false;
  for (std::size_t k = 0; k < n; ++k) {
    if (outside != nullptr && outside[k] != 0) {
      any_outside = true;
      continue;
    }
    if (!std::isfinite(data[k])) {
      any_nonfinite = true;
      continue;
    }
    lo = std::min(lo, data[k]);
    hi = std::max(hi, data[k]);
  }
  const bool have_values = lo <= hi;
  double c_lo = have_values ? lo : 0.0, c_hi = have_values ? hi : 1.0;
  if (!(c_hi - c_lo > 0.0) || !std::isfinite(c_hi - c_lo)) {
    const double half = c_lo != 0.0 ? std::fabs(c_lo) * 0.5 : 1.0;
    if (c_hi == c_lo) {
      c_lo -= half;
      c_hi += half;
    } else {  // overflowing span: fall back to a symmetric, finite range
      c_lo = -std::numeric_limits<double>::max() / 2;
      c_hi = std::numeric_limits<double>::max() / 2;
    }
  }

  const auto [x_lo, x_hi] = node_axis_extent(nx, x_min, x_max);
  const auto [y_lo, y_hi] = node_axis_extent(ny, y_min, y_max);
  constexpr int plot_size = 480;
  const Ticks xt = choose_ticks(x_lo, x_hi, plot_size, 8, true, text_scale, 16);
  const Ticks yt = choose_ticks(y_lo, y_hi, plot_size, 8, false, text_scale, 18);
  const int y_label_w = std::max(widest_label(yt), text_width("-0.00", text_scale));

  // Colour bar: end labels are the data extremes, interior labels a 1-2-5 grid.
  constexpr int bar_gap = 24, bar_w = 18, legend_h = 2 * text_h + 8 + 22;
  const int bar_h = plot_size - legend_h;
  const Ticks ct = choose_ticks(c_lo, c_hi, bar_h, 6, false, text_scale, 24);
  std::vector<std::pair<int, std::string>> bar_labels;  // (offset from bar bottom, text)
  bar_labels.emplace_back(0, format_value(c_lo));
  bar_labels.emplace_back(bar_h - 1, format_value(c_hi));
  for (std::size_t i = 0; i < ct.values.size(); ++i) {
    const int off = axis_pixel(ct.values[i], c_lo, c_hi, bar_h);
    if (off >= text_h + 6 && off <= bar_h - 1 - text_h - 6)
      bar_labels.emplace_back(off, ct.labels[i]);
  }
  int bar_label_w = text_width("0.0000", text_scale);
  for (const auto& bl : bar_labels)
    bar_label_w = std::max(bar_label_w, text_width(bl.second, text_scale));
  const int legend_w = text_h + 6 + text_width("NaN/inf", text_scale);

  PlotFrame f;
  f.plot_x = left_margin(y_label_w);
  f.plot_y = plot_top;
  f.plot_w = plot_size;
  f.plot_h = plot_size;
  const int bar_x = f.plot_x + f.plot_w + 1 + bar_gap;
  f.width = std::max(bar_x + bar_w + tick_len + tick_gap + bar_label_w, bar_x + legend_w) + margin;
  f.height = f.plot_y + f.plot_h + 1 + bottom_margin;
  Canvas cv(f.width, f.height, white);

  // Cells: pixel centre -> node index (nearest neighbour); row 0 is the top (y_max).
  for (int py = 0; py < f.plot_h; ++py) {
    const auto iy =
        ny - 1 -
        std::min(ny - 1, static_cast<std::size_t>((py + 0.5) / f.plot_h * static_cast<double>(ny)));
    for (int px = 0; px < f.plot_w; ++px) {
      const auto ix = std::min(
          nx - 1, static_cast<std::size_t>((px + 0.5) / f.plot_w * static_cast<double>(nx)));
      const std::size_t k = ix * ny + iy;
      Rgb c;
      if (outside != nullptr && outside[k] != 0) {
        c = png_outside_colour;
      } else if (!std::isfinite(data[k])) {
        c = png_nonfinite_colour;
      } else {
        c = viridis((data[k] - c_lo) / (c_hi - c_lo));
      }
      cv.set(f.plot_x + px, f.plot_y + py, c);
    }
  }
  draw_axes(cv, f, xt, x_lo, x_hi, yt, y_lo, y_hi, x_name, y_name, title, y_label_w);

  // Colour bar with frame, ticks and labels.
  const int bar_y = f.plot_y;
  for (int r = 0; r < bar_h; ++r)
    cv.fill_rect(bar_x, bar_y + r, bar_w, 1, viridis(1.0 - (r + 0.5) / bar_h));
  cv.outline_rect(bar_x - 1, bar_y - 1, bar_w + 2, bar_h + 2, axis_ink);
  for (const auto& [off, text] : bar_labels) {
    const int y = bar_y + bar_h - 1 - off;
    cv.fill_rect(bar_x + bar_w + 1, y, tick_len, 1, axis_ink);
    draw_text(cv, bar_x + bar_w + 1 + tick_len + tick_gap, y - text_h / 2, text, text_scale, ink);
  }

  // Legend for the special colours, under the colour bar.
  int legend_y = f.plot_y + f.plot_h - text_h;
  const auto legend_entry = [&](Rgb c, const char* label) {
    cv.fill_rect(bar_x, legend_y, text_h, text_h, c);
    cv.outline_rect(bar_x, legend_y, text_h, text_h, axis_ink);
    draw_text(cv, bar_x + text_h + 6, legend_y, label, text_scale, ink);
    legend_y -= text_h + 8;
  };
  if (any_nonfinite) legend_entry(png_nonfinite_colour, "NaN/inf");
  if (any_outside) legend_entry(png_outside_colour, "outside");

  save_png(path, cv, title);
  return f;
}

/// Renders a line plot of the points (x[i], y[i]) to an RGB PNG at `path` (written
/// atomically): x horizontal increasing to the right, y vertical increasing upward,
/// axes spanning the finite x range and the finite y range plus 5% headroom, 1-2-5
/// ticks with light grid lines, an anti-aliased polyline (broken at NaN/inf points;
/// small markers when there are at most 40 points), axis names and a title. The plot
/// area is 560 x 360 pixels. Returns the geometry. Throws std::invalid_argument if the
/// sizes differ, std::runtime_error for I/O and libpng errors.
inline PlotFrame write_lineplot_png(const std::string& path, std::span<const double> x,
                                    std::span<const double> y, const std::string& x_name,
                                    const std::string& y_name, const std::string& title) {
  using namespace detail;
  if (x.size() != y.size())
    throw std::invalid_argument("line plot: x and y sizes differ for " + path);
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = -x_lo;
  double y_lo = x_lo, y_hi = -x_lo;
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i])) continue;
    x_lo = std::min(x_lo, x[i]);
    x_hi = std::max(x_hi, x[i]);
    y_lo = std::min(y_lo, y[i]);
    y_hi = std::max(y_hi, y[i]);
  }
  const auto widen = [](double& lo, double& hi) {
    if (!(lo <= hi)) {
      lo = 0.0;
      hi = 1.0;
    } else if (!(hi - lo > 0.0) || !std::isfinite(hi - lo)) {
      const double half = lo != 0.0 ? std::fabs(lo) * 0.5 : 1.0;
      lo -= half;
      hi += half;
    }
  };
  widen(x_lo, x_hi);
  widen(y_lo, y_hi);
  const double pad = 0.05 * (y_hi - y_lo);
  y_lo -= pad;
  y_hi += pad;

  constexpr int plot_w = 560, plot_h = 360;
  const Ticks xt = choose_ticks(x_lo, x_hi, plot_w, 10, true, text_scale, 16);
  const Ticks yt = choose_ticks(y_lo, y_hi, plot_h, 8, false, text_scale, 18);
  const int y_label_w = std::max(widest_label(yt), text_width("-0.00", text_scale));
  const int last_half = xt.labels.empty() ? 0 : text_width(xt.labels.back(), text_scale) / 2;

  PlotFrame f;
  f.plot_x = left_margin(y_label_w);
  f.plot_y = plot_top;
  f.plot_w = plot_w;
  f.plot_h = plot_h;
  f.width = f.plot_x + plot_w + 1 + std::max(last_half, 2 * margin) + margin;
  f.height = f.plot_y + plot_h + 1 + bottom_margin;
  Canvas cv(f.width, f.height, white);

  for (const double v : xt.values)
    cv.fill_rect(f.plot_x + axis_pixel(v, x_lo, x_hi, plot_w), f.plot_y, 1, plot_h, grid_ink);
  for (const double v : yt.values)
    cv.fill_rect(f.plot_x, f.plot_y + plot_h - 1 - axis_pixel(v, y_lo, y_hi, plot_h), plot_w, 1,
                 grid_ink);

  const auto to_px = [&](double v) { return f.plot_x + (v - x_lo) / (x_hi - x_lo) * plot_w; };
  const auto to_py = [&](double v) { return f.plot_y + (y_hi - v) / (y_hi - y_lo) * plot_h; };
  CoverageMask mask(f.plot_x, f.plot_y, plot_w, plot_h);
  bool have_prev = false;
  double prev_x = 0.0, prev_y = 0.0;
  std::size_t finite_points = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    if (!std::isfinite(x[i]) || !std::isfinite(y[i])) {
      have_prev = false;
      continue;
    }
    ++finite_points;
    const double px = to_px(x[i]), py = to_py(y[i]);
    if (have_prev) mask.segment(prev_x, prev_y, px, py, 2.0);
    prev_x = px;
    prev_y = py;
    have_prev = true;
  }
  if (finite_points <= 40)
    for (std::size_t i = 0; i < x.size(); ++i)
      if (std::isfinite(x[i]) && std::isfinite(y[i])) mask.disc(to_px(x[i]), to_py(y[i]), 2.5);
  mask.paint(cv, line_ink);

  draw_axes(cv, f, xt, x_lo, x_hi, yt, y_lo, y_hi, x_name, y_name, title, y_label_w);
  save_png(path, cv, title);
  return f;
}

}  // namespace hybgen::rt
