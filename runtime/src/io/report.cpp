// report.html (hybgen/rt/io/report.hpp).

#include "hybgen/rt/io/report.hpp"

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <system_error>
#include <vector>

#include "hybgen/rt/io/atomic_file.hpp"
#include "hybgen/rt/io/run_files.hpp"
#include "hybgen/rt/method_table.hpp"

namespace hybgen::rt {

namespace {

namespace fs = std::filesystem;

/// `s` safe in HTML text and attribute values.
std::string html(const std::string& s) {
  std::string o;
  for (char c : s) switch (c) {
      case '&':
        o += "&amp;";
        break;
      case '<':
        o += "&lt;";
        break;
      case '>':
        o += "&gt;";
        break;
      case '"':
        o += "&quot;";
        break;
      case '\'':
        o += "&#39;";
        break;
      default:
        o += c;
    }
  return o;
}

std::string number(double v) {
  char b[40];
  std::snprintf(b, sizeof b, "%.6g", v);
  return b;
}

std::string text_of(const nlohmann::json& j, const char* key) {
  return j.is_object() && j.contains(key) && j[key].is_string() ? j[key].get<std::string>() : "";
}

bool has(const std::vector<std::string>& files, const std::string& f) {
  return std::find(files.begin(), files.end(), f) != files.end();
}

/// Copy KaTeX's stylesheet, script and woff2 fonts from `from` into `to`; false when
/// `from` has no KaTeX.
bool copy_katex(const fs::path& from, const fs::path& to) {
  std::error_code ec;
  if (!fs::exists(from / "katex.min.css", ec) || !fs::exists(from / "katex.min.js", ec))
    return false;
  fs::create_directories(to / "fonts");
  const auto copy = [&](const fs::path& a, const fs::path& b) {
    // Through the symlinks Debian installs (katex.min.js -> katex.js, fonts -> ../../fonts).
    fs::copy_file(fs::canonical(a), b, fs::copy_options::overwrite_existing);
  };
  copy(from / "katex.min.css", to / "katex.min.css");
  copy(from / "katex.min.js", to / "katex.min.js");
  for (const auto& e : fs::directory_iterator(fs::canonical(from / "fonts")))
    if (e.path().extension() == ".woff2") copy(e.path(), to / "fonts" / e.path().filename());
  return true;
}

}  // namespace

std::string katex_directory() {
  if (const char* d = std::getenv("HYBGEN_KATEX_DIR"); d && *d) return d;
  return "/usr/share/javascript/katex";
}

std::vector<std::string> display_equations(const std::string& latex) {
  std::vector<std::string> out;
  std::istringstream in(latex);
  std::string line, current;
  bool inside = false;
  while (std::getline(in, line)) {
    const std::size_t first = line.find_first_not_of(" \t");
    const std::string trimmed = first == std::string::npos ? "" : line.substr(first);
    if (trimmed.rfind('%', 0) == 0) continue;
    if (trimmed == "\\[") {
      inside = true;
      current.clear();
    } else if (trimmed == "\\]") {
      if (inside) out.push_back(current);
      inside = false;
    } else if (inside) {
      current += line + "\n";
    }
  }
  return out;
}

std::string write_report(const RunRecord& run, const std::vector<std::string>& files,
                         const std::string& dir) {
  const fs::path out(dir);
  std::string warning;
  const bool katex = copy_katex(katex_directory(), out / std::string(kReportAssetsDirectory));
  if (!katex)
    warning = "report.html shows the equations as LaTeX source: KaTeX was not found in '" +
              katex_directory() + "' (install Debian's libjs-katex, or set HYBGEN_KATEX_DIR)";
  const nlohmann::json& pv = run.provenance;
  const bool series = !run.times.empty();
  std::vector<std::string> frames;  // the frame pictures the slider shows
  for (const std::string& f : run.frame_names)
    if (has(files, f + ".png")) frames.push_back(f + ".png");

  std::ostringstream h;
  h << "<!doctype html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
    << "<title>" << html(run.model) << " · hybgen report</title>\n";
  if (katex)
    h << "<link rel=\"stylesheet\" href=\"katex/katex.min.css\">\n"
      << "<script src=\"katex/katex.min.js\"></script>\n";
  h << R"(<style>
body { font-family: "DejaVu Sans", sans-serif; max-width: 1150px; margin: 1.5em auto; color: #222; }
h1 { margin-bottom: 0.2em; } h2 { border-bottom: 1px solid #ddd; padding-bottom: 0.2em; }
.eq { overflow-x: auto; margin: 0.5em 0; }
pre { background: #f6f6f6; padding: 0.8em; overflow-x: auto; font-size: 90%; }
table { border-collapse: collapse; } td, th { padding: 2px 12px; border-bottom: 1px solid #e4e4e4; }
td.n { text-align: right; font-variant-numeric: tabular-nums; }
img { max-width: 100%; } .muted { color: #666; }
#controls { display: flex; gap: 1em; align-items: center; } #slider { flex: 1; }
</style>
</head>
<body>
)";
  h << "<h1>" << html(run.model) << "</h1>\n<p class=\"muted\">" << html(run.method) << " on ";
  for (std::size_t a = 0; a < run.axes.size(); ++a) h << (a ? " × " : "") << run.axes[a].n;
  h << " nodes in (";
  for (std::size_t a = 0; a < run.axes.size(); ++a) h << (a ? ", " : "") << html(run.axis_names[a]);
  h << ")";
  h << ", " << run.n_mode() << " mode" << (run.n_mode() == 1 ? "" : "s");
  if (series) h << ", " << run.times.size() << " output times to t = " << number(run.times.back());
  h << " · "
    << html(text_of(pv, "hybgen_version").empty() ? "hybgen"
                                                  : "hybgen " + text_of(pv, "hybgen_version"))
    << "</p>\n";

  // The density.
  h << "<h2>" << (series ? "The density" : "The invariant density") << "</h2>\n";
  if (!frames.empty()) {
    h << "<img id=\"frame\" src=\"" << html(frames.front()) << "\" alt=\"the density\">\n";
    if (frames.size() > 1)
      h << "<div id=\"controls\"><button id=\"play\">play</button>"
        << "<input id=\"slider\" type=\"range\" min=\"0\" max=\"" << frames.size() - 1
        << "\" value=\"0\"><span id=\"time\"></span></div>\n";
  } else if (has(files, "animation.gif")) {
    h << "<img src=\"animation.gif\" alt=\"the density, animated\">\n";
  } else {
    h << "<p class=\"muted\">No pictures were written (outputs=…+png).</p>\n";
  }
  if (has(files, "density.pdf"))
    h << "<p class=\"muted\">Every frame for print: <a href=\"density.pdf\">density.pdf</a>"
      << (has(files, "animation.gif") ? ", animated: <a href=\"animation.gif\">animation.gif</a>"
                                      : "")
      << ".</p>\n";
  // Cell averages (characteristics, values=cells): what the frames hold, and how well.
  if (run.cell_averages && run.summary.is_object() && run.summary.contains(summary_key::values)) {
    const nlohmann::json& v = run.summary[summary_key::values];
    double worst = 0.0;
    for (const auto& e : v.value("error", nlohmann::json::array()))
      if (e.is_number()) worst = std::max(worst, e.get<double>());
    h << "<p>The frames are <b>cell averages</b>: each value is the exact density's mean over "
         "its node's dual cell, by adaptive cubature (estimated L1 error at most "
      << number(worst) << " of the mass), because " << html(v.value("reason", std::string()))
      << ".</p>\n";
  }

  // The mass budget.
  const MassBudget& b = run.budget;
  if (series && b.mass.size() == run.times.size() && !b.mass.empty()) {
    h << "<h2>Mass budget</h2>\n";
    if (has(files, "budget.png")) h << "<img src=\"budget.png\" alt=\"the mass budget\">\n";
    const std::size_t k = b.mass.size() - 1;
    const std::vector<double> defect = budget_defect(b), bar = budget_defect_error(b);
    h << "<table>\n<tr><th>at t = " << number(run.times[k])
      << "</th><th>value</th><th>± estimate</th></tr>\n";
    const auto row = [&](const char* name, double v, double e) {
      h << "<tr><td>" << name << "</td><td class=\"n\">" << number(v) << "</td><td class=\"n\">"
        << (e > 0 ? number(e) : "") << "</td></tr>\n";
    };
    row("initial mass", b.mass0, b.mass0_error);
    row("mass in the box", b.mass[k], k < b.mass_error.size() ? b.mass_error[k] : 0);
    row("outflow", b.outflow[k], k < b.outflow_error.size() ? b.outflow_error[k] : 0);
    row("atom (Zeno)", b.atom[k], k < run.atom_error.size() ? run.atom_error[k] : 0);
    // Each trap's share of the outflow (`reset absorb`).
    if (run.summary.is_object() && run.summary.contains(summary_key::absorbed))
      for (const auto& [guard, a] : run.summary[summary_key::absorbed].items()) {
        const nlohmann::json& v = a["values"];
        const nlohmann::json& e = a["errors"];
        if (!v.is_array() || k >= v.size() || !v[k].is_number()) continue;
        const std::string name = "absorbed by guard " + html(guard) + " (part of outflow)";
        row(name.c_str(), v[k].get<double>(),
            e.is_array() && k < e.size() && e[k].is_number() ? e[k].get<double>() : 0.0);
      }
    row("unaccounted", defect[k], bar[k]);
    h << "</table>\n";
    // The transfer operator's estimated error at this time (methods.hpp, add_transfer_errors).
    if (run.summary.is_object() && run.summary.contains(summary_key::transfer)) {
      const nlohmann::json& t = run.summary[summary_key::transfer];
      const nlohmann::json errors = t.value("errors", nlohmann::json());
      const nlohmann::json ok = t.value("errors_reliable", nlohmann::json());
      if (errors.is_array() && k < errors.size() && errors[k].is_number())
        h << "<p>estimated error of the density at t = " << number(run.times[k]) << ": "
          << number(errors[k].get<double>()) << " (relative L1, from the grid of "
          << html(t.value("coarse_grid", nlohmann::json()).dump()) << " nodes)"
          << (ok.is_array() && k < ok.size() && ok[k] == false
                  ? "; <b>unreliable</b>: the difference does not fall with the grid spacing"
                  : "")
          << "</p>\n";
    }
  }
  // The impacts on each guard by the last frame and their last mean rate (methods/impacts.hpp).
  if (run.summary.is_object() && run.summary.contains(summary_key::impacts) &&
      !run.summary[summary_key::impacts].empty() && !run.times.empty()) {
    h << "<h2>Impacts</h2>\n<p>The mass that has crossed each guard, counted once per crossing, "
         "and the mean rate at which it crosses over the last interval (docs/methods.md, "
         "\"Impacts\").</p>\n";
    if (has(files, "impacts.png"))
      h << "<img src=\"impacts.png\" alt=\"the impact rates on the guards over time\">\n";
    h << "<table>\n<tr><th>guard</th><th>impacts by t = " << number(run.times.back())
      << "</th><th>± estimate</th><th>rate</th><th>± estimate</th></tr>\n";
    const auto cell = [&](const nlohmann::json& x) {
      return x.is_array() && !x.empty() && x.back().is_number() ? number(x.back().get<double>())
                                                                : std::string();
    };
    for (const auto& [guard, a] : run.summary[summary_key::impacts].items()) {
      h << "<tr><td>" << html(guard) << "</td>";
      if (a["infinite_from"].is_number())
        h << "<td colspan=\"4\">infinite from t = " << number(a["infinite_from"].get<double>())
          << " (mass at a Zeno point)</td></tr>\n";
      else
        h << "<td class=\"n\">" << cell(a["values"]) << "</td><td class=\"n\">" << cell(a["errors"])
          << "</td><td class=\"n\">" << cell(a["rate"]) << "</td><td class=\"n\">"
          << cell(a["rate_errors"]) << "</td></tr>\n";
    }
    h << "</table>\n";
  }
  // The observables at the last frame, with their errors (methods/observables.hpp).
  if (run.summary.is_object() && run.summary.contains(summary_key::observables) &&
      !run.summary[summary_key::observables].empty()) {
    h << "<h2>Observables</h2>\n";
    if (has(files, "observables.png"))
      h << "<img src=\"observables.png\" alt=\"the observables' means over time\">\n";
    h << "<table>\n<tr><th>mean under the density"
      << (series ? " at t = " + number(run.times.back()) : std::string())
      << "</th><th>value</th><th>± estimate</th></tr>\n";
    for (const auto& [name, o] : run.summary[summary_key::observables].items()) {
      const nlohmann::json& v = o["values"];
      const nlohmann::json& e = o["errors"];
      if (v.empty()) continue;
      h << "<tr><td>E[" << html(name) << "]</td><td class=\"n\">"
        << (v.back().is_number() ? number(v.back().get<double>()) : "undefined")
        << "</td><td class=\"n\">" << (e.back().is_number() ? number(e.back().get<double>()) : "")
        << "</td></tr>\n";
    }
    h << "</table>\n<p>" << html(run.summary[summary_key::observables].begin()->value("note", ""))
      << "</p>\n";
  }
  if (run.summary.is_object() && run.summary.contains(summary_key::invariant)) {
    const nlohmann::json& inv = run.summary[summary_key::invariant];
    h << "<h2>Spectrum</h2>\n";
    if (has(files, "spectrum.png")) h << "<img src=\"spectrum.png\" alt=\"the spectrum\">\n";
    // The rates with their errors and the decisions they support (methods/two_grid.hpp).
    const auto with_error = [&](const char* key) {
      const std::string e = std::string(key) + "_error";
      std::string text = number(inv.value(key, 0.0));
      if (inv.contains(e) && inv[e].is_number()) text += " ± " + number(inv[e].get<double>());
      return text;
    };
    const auto is = [&](const char* key, bool value) {
      return inv.contains(key) && inv[key].is_boolean() && inv[key].get<bool>() == value;
    };
    h << "<p>spectral gap " << with_error("spectral_gap") << ", decay rate "
      << with_error("decay_rate") << " per unit time"
      << (is("decays", false) ? ": the gap is within its error of 0, so no decay is claimed" : "")
      << "</p>\n";
    if (is("leaks", true))
      h << "<p>leak rate " << with_error("leak_rate")
        << " per unit time: mass leaves the box, so no density in it is invariant; the frame "
           "is the conditionally invariant density (method=escape gives the escape rate)</p>\n";
    if (inv.contains("error") && inv["error"].is_number())
      h << "<p>estimated error of the density " << number(inv["error"].get<double>())
        << " (relative L1, from the grid of "
        << html(inv.value("coarse_grid", nlohmann::json()).dump()) << " nodes)"
        << (is("error_reliable", false)
                ? "; <b>unreliable</b>: the observed order of convergence is not the scheme's"
                : "")
        << "</p>\n";
  }

  if (run.summary.is_object() && run.summary.contains(summary_key::escape)) {
    const nlohmann::json& e = run.summary[summary_key::escape];
    h << "<h2>Escape rate</h2>\n<p>escape rate " << number(e.value("rate", 0.0)) << " ± "
      << number(e.value("rate_error", 0.0))
      << " per unit time (λ<sub>1</sub> = " << number(e.value("lambda1", 0.0)) << " per step of "
      << number(e.value("step", 0.0))
      << "); the frame is the conditionally invariant density, of unit mass</p>\n";
  }

  // A set's or pair's number in the tables below ("–": none, a null error).
  const auto cell = [&](const nlohmann::json& set, const char* key) {
    return set.contains(key) && set[key].is_number() ? number(set[key].get<double>())
                                                     : std::string("–");
  };

  // The almost-invariant sets (methods/almost_invariant.hpp): a table and their picture.
  if (run.summary.is_object() && run.summary.contains(summary_key::almost_invariant)) {
    const nlohmann::json& a = run.summary[summary_key::almost_invariant];
    h << "<h2>Almost-invariant sets</h2>\n<p>K regions whose invariant mass stays in them over "
         "a step of "
      << number(a.value("step", 0.0))
      << " with the highest probability (the ratio); the frame is the invariant density</p>\n"
         "<table>\n<tr><th>set</th><th>mass</th><th>ratio</th><th>exit rate (per unit "
         "time)</th></tr>\n";
    for (const nlohmann::json& set : a.value("sets", nlohmann::json::array()))
      h << "<tr><td>" << set.value("set", 0) << "</td><td>" << cell(set, "mass") << " ± "
        << cell(set, "mass_error") << "</td><td>" << cell(set, "ratio") << " ± "
        << cell(set, "ratio_error") << "</td><td>" << cell(set, "exit_rate") << "</td></tr>\n";
    h << "</table>\n<p>sum of the ratios " << number(a.value("ratio_sum", 0.0)) << " ≤ "
      << number(a.value("bound", 0.0))
      << " (the sum of the reversibilised operator's leading eigenvalues); mass in no set "
      << number(a.value("unassigned_mass", 0.0)) << "</p>\n";
    if (has(files, "sets.png")) h << "<img src=\"sets.png\" alt=\"the almost-invariant sets\">\n";
  }

  // The coherent pairs (methods/coherent.hpp): a table and their picture at both times.
  if (run.summary.is_object() && run.summary.contains(summary_key::coherent)) {
    const nlohmann::json& a = run.summary[summary_key::coherent];
    const auto pm = [&](const nlohmann::json& set, const char* key, const std::string& error) {
      return cell(set, key) + " ± " + cell(set, error.c_str());
    };
    h << "<h2>Coherent pairs</h2>\n<p>K pairs of regions, A at t = 0 and B at t = "
      << number(a.value("t_end", 0.0))
      << ", such that the initial density's mass in A is carried into B (forward: the "
         "probability that mass in A ends in B; backward: that mass in B came from "
         "A)</p>\n<table>\n<tr><th>pair</th><th>mass of A</th><th>mass of B</th><th>forward"
         "</th><th>backward</th></tr>\n";
    for (const nlohmann::json& set : a.value("sets", nlohmann::json::array()))
      h << "<tr><td>" << set.value("set", 0) << "</td><td>"
        << pm(set, "initial_mass", "initial_mass_error") << "</td><td>"
        << pm(set, "final_mass", "final_mass_error") << "</td><td>"
        << pm(set, "forward", "forward_error") << "</td><td>"
        << pm(set, "backward", "backward_error") << "</td></tr>\n";
    h << "</table>\n<p>sum of √(forward·backward) " << number(a.value("coherence_sum", 0.0))
      << " ≤ " << number(a.value("bound", 0.0))
      << " (the sum of the normalised transport's leading singular values)</p>\n";
    if (has(files, "sets.png"))
      h << "<img src=\"sets.png\" alt=\"the coherent pairs at t = 0 and at t_end\">\n";
  }

  // What derive checked.
  if (pv.is_object() && pv.contains("checks") && pv["checks"].is_object()) {
    const nlohmann::json& c = pv["checks"];
    h << "<h2>Hypotheses and checks</h2>\n<ul>\n";
    static const std::vector<std::pair<std::string, std::string>> hypotheses = {
        {"normal", "the impact surface is a coset of a normal subgroup"},
        {"codim1", "the subgroup has codimension one"},
        {"left_invariant", "the Hamiltonian is left-invariant"},
        {"transversal", "the flow crosses the impact surface transversally"}};
    if (c.contains("hypotheses") && c["hypotheses"].is_object())
      for (const auto& [key, words] : hypotheses)
        if (c["hypotheses"].contains(key))
          h << "<li>" << (c["hypotheses"][key].get<bool>() ? "&#10003; " : "&#10007; ")
            << html(words) << " (<code>" << html(key) << "</code>)</li>\n";
    if (c.contains("guards"))
      for (const auto& g : c["guards"]) {
        const std::string kind = g.value("reset_inverse_kind", "");
        h << "<li>guard <code>" << html(g.value("name", "")) << "</code>: "
          << (kind == "symbolic" ? std::string("the reset has a closed-form inverse")
              : kind == "guard"
                  ? std::string("the reset is constant in one component and is inverted on "
                                "its guard")
              : kind == "none"
                  ? std::string("the reset has no inverse off its guard (forward methods only)")
                  : std::string("the reset is inverted numerically (Newton)"))
          << "</li>\n";
      }
    if (c.contains("warnings") && c["warnings"].is_array() && !c["warnings"].empty())
      for (const auto& w : c["warnings"])
        h << "<li>&#9888; " << html(w.is_string() ? w.get<std::string>() : w.dump()) << "</li>\n";
    else
      h << "<li>derive gave no warnings</li>\n";
    h << "</ul>\n";
  }

  // The equations.
  const std::vector<std::string> eqs = display_equations(text_of(pv, "equations_latex"));
  h << "<h2>Derived equations</h2>\n";
  for (const std::string& e : eqs)
    h << "<div class=\"eq\" data-tex=\"" << html(e) << "\">"
      << (katex ? "" : "<pre>" + html(e) + "</pre>") << "</div>\n";
  if (const std::string t = text_of(pv, "equations"); !t.empty())
    h << "<details><summary>As <code>hybgen derive</code> prints them</summary><pre>" << html(t)
      << "</pre></details>\n";

  // The model.
  h << "<h2>Model</h2>\n<p class=\"muted\">" << html(text_of(pv, "model_path")) << " · SHA-256 "
    << html(text_of(pv, "model_sha256")) << "</p>\n<pre>" << html(text_of(pv, "model_text"))
    << "</pre>\n<p>Parameters: ";
  for (std::size_t j = 0; j < run.params.size(); ++j)
    h << (j ? ", " : "") << html(run.param_names[j]) << " = " << number(run.params[j]);
  h << "</p>\n";

  // Timings and files.
  if (run.summary.is_object() && run.summary.contains(summary_key::seconds)) {
    h << "<h2>Timings</h2>\n<table>\n";
    for (const auto& [key, value] : run.summary[summary_key::seconds].items())
      if (value.is_number())
        h << "<tr><td>" << html(key) << "</td><td class=\"n\">" << number(value.get<double>())
          << " s</td></tr>\n";
    h << "</table>\n";
  }
  h << "<h2>Files</h2>\n<p>";
  bool first = true;
  for (const std::string& f : files) {
    if (f.ends_with(".png") && f.rfind("u_", 0) == 0) continue;  // the frames: the slider's
    h << (first ? "" : " · ") << "<a href=\"" << html(f) << "\">" << html(f) << "</a>";
    first = false;
  }
  h << (frames.empty() ? "" : " · frames u_0000.png … ")
    << " · <a href=\"summary.json\">summary.json</a></p>\n";

  // The script: frames, the slider, KaTeX, the self-test.
  nlohmann::json jf = frames, jt = run.times;
  h << "<script>\nconst frames = " << jf.dump() << ", times = " << jt.dump() << ";\n"
    << R"(const img = document.getElementById('frame'), slider = document.getElementById('slider');
const label = document.getElementById('time'), play = document.getElementById('play');
function show(k) {
  if (!img || !frames.length) return;
  img.setAttribute('src', frames[k]);
  if (label && times.length) label.textContent = 't = ' + times[k].toFixed(3);
}
if (slider) {
  slider.addEventListener('input', () => show(+slider.value));
  show(0);
  let timer = null;
  play.addEventListener('click', () => {
    if (timer) { clearInterval(timer); timer = null; play.textContent = 'play'; return; }
    play.textContent = 'pause';
    timer = setInterval(() => { slider.value = (+slider.value + 1) % frames.length; show(+slider.value); },
                        Math.max(40, 6000 / frames.length));
  });
}
let rendered = 0, failed = 0;
document.querySelectorAll('.eq').forEach(el => {
  if (typeof katex === 'undefined') return;
  try { katex.render(el.dataset.tex, el, {displayMode: true, throwOnError: true}); rendered++; }
  catch (e) { failed++; el.innerHTML = '<pre>' + el.dataset.tex.replace(/</g, '&lt;') + '</pre>'; }
});
if (location.hash === '#selftest') {
  const last = frames.length ? frames[frames.length - 1] : '';
  if (slider) { slider.value = frames.length - 1; slider.dispatchEvent(new Event('input')); }
  const shown = img ? img.getAttribute('src') : '';
  const ok = rendered === document.querySelectorAll('.eq').length && rendered > 0 && failed === 0 &&
             shown === last;
  document.title = (ok ? 'selftest ok' : 'selftest failed') + ': ' + rendered + ' equations rendered, ' +
                   failed + ' failed, frame ' + shown;
}
</script>
</body>
</html>
)";
  write_file_atomic((out / "report.html").string(), h.str());
  return warning;
}

}  // namespace hybgen::rt
