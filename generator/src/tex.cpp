// TeX names of identifiers (tex.hpp).

#include "hybgen/gen/tex.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <string_view>

namespace hybgen::gen {

namespace {

constexpr std::array<std::string_view, 32> kGreek = {
    "alpha",  "beta",  "gamma",  "delta", "epsilon", "zeta",  "eta",   "theta",
    "iota",   "kappa", "lambda", "mu",    "nu",      "xi",    "rho",   "sigma",
    "tau",    "phi",   "chi",    "psi",   "omega",   "Gamma", "Delta", "Theta",
    "Lambda", "Xi",    "Pi",     "Sigma", "Phi",     "Psi",   "Omega", "pi"};

bool is_greek(std::string_view s) {
  return std::find(kGreek.begin(), kGreek.end(), s) != kGreek.end();
}

std::string escape_underscores(const std::string& s) {
  std::string out;
  for (char c : s) out += c == '_' ? std::string("\\_") : std::string(1, c);
  return out;
}

}  // namespace

std::string tex_identifier(const std::string& name) {
  const std::size_t us = name.find('_');
  if (us != std::string::npos && us > 0 && us + 1 < name.size())
    return tex_identifier(name.substr(0, us)) + "_{" + tex_identifier(name.substr(us + 1)) + "}";
  std::size_t k = name.size();
  while (k > 0 && std::isdigit(static_cast<unsigned char>(name[k - 1]))) --k;
  const std::string base = name.substr(0, k), sub = name.substr(k);
  std::string t;
  if (base.empty())
    t = "";
  else if (is_greek(base))
    t = "\\" + base;
  else if (base.size() == 1)
    t = base;
  else
    t = "\\mathrm{" + escape_underscores(base) + "}";
  if (!sub.empty()) t = base.empty() ? sub : t + "_{" + sub + "}";
  return t;
}

std::string tex_dot(const std::string& tex) {
  int depth = 0;
  for (std::size_t i = 0; i < tex.size(); ++i) {
    if (tex[i] == '{') ++depth;
    if (tex[i] == '}') --depth;
    if (tex[i] == '_' && depth == 0 && i > 0 && tex[i - 1] != '\\')
      return "\\dot{" + tex.substr(0, i) + "}" + tex.substr(i);
  }
  return "\\dot{" + tex + "}";
}

std::string tex_label(const std::string& name) {
  return "\\mathrm{" + escape_underscores(name) + "}";
}

}  // namespace hybgen::gen
