#pragma once
/// \file tex.hpp
/// How a model's names are written in LaTeX, defined once (the checker, the reduction and
/// the unreduced twin give every state and parameter its TeX name; the emitter uses them).

#include <string>

namespace hybgen::gen {

/// The LaTeX of an identifier, for math mode:
///  - a Greek letter's name is the letter (`theta` → `\theta`, `Omega` → `\Omega`);
///  - trailing digits are a subscript (`theta0` → `\theta_{0}`);
///  - the part after the first '_' is a subscript, itself an identifier
///    (`T_out` → `T_{\mathrm{out}}`, `x_1` → `x_{1}`, `p_theta` → `p_{\theta}`);
///  - other names of several letters are upright (`Vmax` → `\mathrm{Vmax}`), with any other
///    underscore escaped (`x_` → `\mathrm{x\_}`).
std::string tex_identifier(const std::string& name);

/// The time derivative of a TeX name: the dot over its base, not over its subscript
/// (`T_{\mathrm{room}}` → `\dot{T}_{\mathrm{room}}`, `\theta` → `\dot{\theta}`).
std::string tex_dot(const std::string& tex);

/// A mode's or guard's name as upright text in math mode (`A_to_B` → `\mathrm{A\_to\_B}`).
std::string tex_label(const std::string& name);

}  // namespace hybgen::gen
