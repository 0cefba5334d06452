// `hybgen sweep` (sweep.hpp): the axes, the points, the parallel runs and the table.

#include "hybgen/gen/sweep.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <iostream>
#include <map>
#include <set>
#include <thread>

#include "hybgen/gen/errors.hpp"
#include "hybgen/gen/fs.hpp"
#include "hybgen/gen/outputs.hpp"
#include "hybgen/gen/process.hpp"
#include "hybgen/rt/io/json_text.hpp"
#include "hybgen/rt/method_table.hpp"

namespace hybgen::gen {

namespace fs = std::filesystem;

namespace {

std::string trim(std::string s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  return s.substr(b, s.find_last_not_of(" \t") - b + 1);
}

/// `text` as a whole number (std::from_chars: no sign prefix '+', no trailing characters).
bool parse_number(const std::string& text, double& value) {
  const char* end = text.data() + text.size();
  const auto [p, ec] = std::from_chars(text.data(), end, value);
  return ec == std::errc() && p == end && std::isfinite(value);
}

/// The shortest decimal that reads back as `v` (std::to_chars): a table's numbers, exactly.
std::string shortest(double v) {
  char buf[64];
  const auto [p, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return std::string(buf, ec == std::errc() ? p : buf);
}

/// `v` to 15 significant digits, as few as that takes (0.30000000000000004 is 0.3, 2e5 is
/// 200000): a range's values, which the points then run with exactly as written.
std::string range_value(double v) {
  char buf[64];
  const auto [p, ec] = std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, 15);
  return std::string(buf, ec == std::errc() ? p : buf);
}

/// The N values of `A:B:N` for `key`.
std::vector<std::string> range_values(const std::string& key, const std::string& value) {
  const auto c1 = value.find(':'), c2 = value.find(':', c1 + 1);
  double a = 0, b = 0, n = 0;
  const bool ok = c2 != std::string::npos && value.find(':', c2 + 1) == std::string::npos &&
                  parse_number(trim(value.substr(0, c1)), a) &&
                  parse_number(trim(value.substr(c1 + 1, c2 - c1 - 1)), b) &&
                  parse_number(trim(value.substr(c2 + 1)), n);
  if (!ok || n < 1 || n != std::floor(n))
    throw UsageError("--set " + key + "=" + value +
                     ": a sweep range is A:B:N, N >= 1 equally spaced numbers from A to B");
  if (n > static_cast<double>(kMaxSweepPoints))
    throw UsageError("--set " + key + "=" + value + ": more than " +
                     std::to_string(kMaxSweepPoints) + " values");
  const auto count = static_cast<std::size_t>(n);
  std::vector<std::string> out{range_value(a)};
  // Both ends exactly; the values between by one rounding each.
  for (std::size_t i = 1; i + 1 < count; ++i)
    out.push_back(
        range_value(a + (b - a) * static_cast<double>(i) / static_cast<double>(count - 1)));
  if (count > 1) out.push_back(range_value(b));
  return out;
}

/// `value` split at its commas outside brackets (a domain [a,b] is one element).
std::vector<std::string> split_top_level(const std::string& value) {
  std::vector<std::string> out;
  std::string cur;
  int depth = 0;
  for (const char c : value) {
    if (c == '[' || c == '(' || c == '{') ++depth;
    if (c == ']' || c == ')' || c == '}') --depth;
    if (c == ',' && depth == 0) {
      out.push_back(trim(cur));
      cur.clear();
    } else {
      cur += c;
    }
  }
  out.push_back(trim(cur));
  return out;
}

/// The elements of the list `v1,v2,...` (or `{v1,v2,...}`) for `key`.
std::vector<std::string> list_values(const std::string& key, const std::string& value) {
  const bool braces = value.size() >= 2 && value.front() == '{' && value.back() == '}';
  const std::vector<std::string> out =
      split_top_level(braces ? value.substr(1, value.size() - 2) : value);
  for (const auto& v : out)
    if (v.empty())
      throw UsageError("--set " + key + "=" + value +
                       ": a sweep list is v1,v2,... with no empty element");
  return out;
}

/// The last entry of the array `j[key]`, if it is a non-empty array of numbers.
void put_last(nlohmann::ordered_json& row, const std::string& name, const nlohmann::json& j,
              const std::string& key) {
  if (j.is_object() && j.contains(key) && j[key].is_array() && !j[key].empty() &&
      j[key].back().is_number())
    row[name] = j[key].back();
}

/// `j[key]` if it is a number.
void put_number(nlohmann::ordered_json& row, const std::string& name, const nlohmann::json& j,
                const std::string& key) {
  if (j.is_object() && j.contains(key) && j[key].is_number()) row[name] = j[key];
}

/// A CSV cell: numbers exactly, strings quoted when they hold a comma, quote or newline.
std::string csv_cell(const nlohmann::ordered_json& v) {
  if (v.is_null()) return "";
  if (v.is_number_float()) return shortest(v.get<double>());
  if (!v.is_string()) return v.dump();
  const std::string s = v.get<std::string>();
  if (s.find_first_of(",\"\r\n") == std::string::npos) return s;
  std::string q = "\"";
  for (char c : s) q += c == '"' ? std::string("\"\"") : std::string(1, c);
  return q + "\"";
}

/// The value of KEY=VALUE as the table shows it: a number when it reads as one.
nlohmann::ordered_json table_value(const std::string& value) {
  double d = 0;
  if (parse_number(value, d)) return d;
  return value;
}

/// One point of a sweep while it runs.
struct Point {
  std::vector<std::string> sets;  ///< The axes' KEY=VALUE.
  std::string label;              ///< Its directory's name.
  const Frontend* fe = nullptr;   ///< Derived with the fixed and the point's overrides.
  std::string config;             ///< Its configuration file.
  int rc = -1;                    ///< Exit code (-1 while not run).
  nlohmann::json summary;         ///< Its summary.json, once it ran.
};

/// The warnings a run's summary holds: the method's and the outputs'.
std::size_t warning_count(const nlohmann::json& s) {
  std::size_t n = 0;
  for (const char* key : {rt::summary_key::warnings, rt::summary_key::output_warnings})
    if (s.contains(key) && s[key].is_array()) n += s[key].size();
  return n;
}

/// Read the summary.json of point `p`, which its runner wrote into `dir` and ended with exit 0;
/// a summary that cannot be read makes the point a failure (exit 70, said on stderr). Returns
/// what its "ok" should not hide: a budget that does not close or stopped short of its
/// tolerance, or how many warnings its
/// runner gave (on stderr marked with the point's name, several points running at once).
std::string finish_point(Point& p, const std::filesystem::path& dir) {
  try {
    p.summary = nlohmann::json::parse(read_file((dir / "summary.json").string()));
  } catch (const std::exception& e) {
    std::cerr << "hybgen: sweep point " << p.label << ": " << e.what() << "\n";
    p.rc = static_cast<int>(ExitCode::Internal);
    return "";
  }
  if (p.summary.contains("budget") && p.summary["budget"].value("closes", true) == false)
    return ", but its mass budget does not close (the warning above; column budget_closes)";
  if (p.summary.contains("budget") && p.summary["budget"].value("converged", true) == false)
    return ", but its mass budget stopped short of its tolerance (its errors say how far it "
           "got; column budget_converged)";
  if (const std::size_t warnings = warning_count(p.summary); warnings > 0)
    return ", with " + std::to_string(warnings) + " warning" + (warnings > 1 ? "s" : "") +
           " (above, marked [" + p.label + "]; column warnings)";
  return "";
}

}  // namespace

SweepSpec parse_sweep(const std::vector<std::string>& sets) {
  SweepSpec spec;
  std::set<std::string> keys;
  for (const auto& s : sets) {
    const auto eq = s.find('=');
    if (eq == std::string::npos || eq == 0)
      throw UsageError("--set expects KEY=VALUE, got '" + s + "'");
    const std::string key = trim(s.substr(0, eq)), value = trim(s.substr(eq + 1));
    if (!keys.insert(key).second)
      throw UsageError("--set " + key + " is given twice (a list of values is " + key +
                       "=v1,v2,...; a shell expands an unquoted {v1,v2} into two --set)");
    if ((value.size() >= 2 && value.front() == '{' && value.back() == '}') ||
        split_top_level(value).size() > 1)
      spec.axes.push_back({key, list_values(key, value)});
    else if (value.find(':') != std::string::npos)
      spec.axes.push_back({key, range_values(key, value)});
    else
      spec.fixed.push_back(s);
  }
  if (spec.axes.empty())
    throw UsageError(
        "a sweep needs at least one --set KEY=A:B:N or KEY=v1,v2,... (hybgen sweep --help)");
  double count = 1;
  for (const auto& a : spec.axes) count *= static_cast<double>(a.values.size());
  if (count > static_cast<double>(kMaxSweepPoints))
    throw UsageError("the sweep has " + shortest(count) + " points, more than " +
                     std::to_string(kMaxSweepPoints));
  return spec;
}

std::vector<std::vector<std::string>> sweep_points(const SweepSpec& spec) {
  std::vector<std::vector<std::string>> points{{}};
  for (const auto& axis : spec.axes) {
    std::vector<std::vector<std::string>> next;
    for (const auto& p : points)
      for (const auto& v : axis.values) {
        next.push_back(p);
        next.back().push_back(axis.key + "=" + v);
      }
    points = std::move(next);
  }
  return points;
}

std::string sweep_label(std::size_t index, std::size_t count,
                        const std::vector<std::string>& point) {
  const std::size_t width = std::to_string(count > 0 ? count - 1 : 0).size();
  std::string label = std::to_string(index);
  label.insert(0, width - std::min(width, label.size()), '0');
  for (const auto& kv : point) {
    label += '_';
    // Each KEY=VALUE to 48 characters (a long expression would pass NAME_MAX); the index
    // keeps labels unique.
    for (char c : kv.substr(0, 48))
      label += std::isalnum(static_cast<unsigned char>(c)) || std::strchr("._=+-", c) ? c : '_';
  }
  return label;
}

nlohmann::ordered_json sweep_row(const nlohmann::json& s) {
  namespace k = rt::summary_key;
  nlohmann::ordered_json row = nlohmann::ordered_json::object();
  if (s.contains(k::method)) row["method"] = s[k::method];
  put_last(row, "t", s, k::times);
  if (s.contains(k::mass) && s[k::mass].is_array() && !s[k::mass].empty())
    put_number(row, "initial_mass", s, k::initial_mass);
  put_last(row, "mass", s, k::mass);
  put_last(row, "mass_error", s, k::mass_error);  // particles: the 2-sigma estimate
  put_last(row, "outflow", s, k::outflow);
  put_last(row, "atom", s, k::atom);
  put_last(row, "atom_error", s, k::atom_error);
  if (s.contains(k::budget)) {
    const auto& b = s[k::budget];
    put_last(row, "mass_error", b, "mass_error");
    put_last(row, "outflow_error", b, "outflow_error");
    put_last(row, "unaccounted", b, "defect");
    put_last(row, "unaccounted_error", b, "defect_error");
    if (b.contains("closes") && b["closes"].is_boolean()) row["budget_closes"] = b["closes"];
    // false: a cubature stopped at its point cap (budget=fast in 4-D and above, typically),
    // and the error columns are as wide as that left them.
    if (b.contains("converged") && b["converged"].is_boolean())
      row["budget_converged"] = b["converged"];
  }
  if (s.contains(k::transfer)) put_number(row, "unaccounted", s[k::transfer], "budget_defect");
  if (s.contains(k::invariant)) {
    const auto& inv = s[k::invariant];
    put_number(row, "spectral_gap", inv, "spectral_gap");
    put_number(row, "decay_rate", inv, "decay_rate");
    put_number(row, "leak_rate", inv, "leak_rate");
    if (inv.contains("eigenvalues") && inv["eigenvalues"].is_array())
      for (std::size_t i = 0; i < inv["eigenvalues"].size(); ++i)
        put_number(row, "abs_lambda" + std::to_string(i + 1), inv["eigenvalues"][i], "abs");
  }
  if (s.contains(k::escape)) {
    put_number(row, "escape_rate", s[k::escape], "rate");
    put_number(row, "escape_rate_error", s[k::escape], "rate_error");
  }
  // Each almost-invariant set's mass and invariance ratio with their errors (set1_mass, …).
  if (s.contains(k::almost_invariant) && s[k::almost_invariant].contains("sets"))
    for (const auto& set : s[k::almost_invariant]["sets"]) {
      const std::string p = "set" + std::to_string(set.value("set", 0));
      for (const char* key : {"mass", "mass_error", "ratio", "ratio_error"})
        put_number(row, p + "_" + key, set, key);
    }
  // Each coherent pair's masses and ratios with their errors (pair1_forward, …).
  if (s.contains(k::coherent) && s[k::coherent].contains("sets"))
    for (const auto& set : s[k::coherent]["sets"]) {
      const std::string p = "pair" + std::to_string(set.value("set", 0));
      for (const char* key :
           {"initial_mass", "initial_mass_error", "final_mass", "final_mass_error", "forward",
            "forward_error", "backward", "backward_error"})
        put_number(row, p + "_" + key, set, key);
    }
  // Each trap's absorbed mass at the final time and its error (absorbed_NAME, …_error).
  if (s.contains(k::absorbed) && s[k::absorbed].is_object())
    for (const auto& [name, a] : s[k::absorbed].items()) {
      put_last(row, "absorbed_" + name, a, "values");
      put_last(row, "absorbed_" + name + "_error", a, "errors");
    }
  // The impacts on each guard by the final time and their last mean rate, with errors
  // (impacts_NAME, impact_rate_NAME, …_error; empty cells where they are infinite).
  if (s.contains(k::impacts) && s[k::impacts].is_object())
    for (const auto& [name, a] : s[k::impacts].items()) {
      put_last(row, "impacts_" + name, a, "values");
      put_last(row, "impacts_" + name + "_error", a, "errors");
      put_last(row, "impact_rate_" + name, a, "rate");
      put_last(row, "impact_rate_" + name + "_error", a, "rate_errors");
    }
  // Each observable's mean at the final time and its error (E_NAME, E_NAME_error).
  if (s.contains(k::observables) && s[k::observables].is_object())
    for (const auto& [name, o] : s[k::observables].items()) {
      put_last(row, "E_" + name, o, "values");
      put_last(row, "E_" + name + "_error", o, "errors");
    }
  // The warnings of the run (their texts: the point's summary.json, and stderr with the
  // point's name).
  row["warnings"] = warning_count(s);
  if (s.contains(k::seconds))
    for (const char* key : {"derive", "build", "solve", "budget", "output"})
      put_number(row, std::string("seconds_") + key, s[k::seconds], key);
  return row;
}

std::string sweep_csv(const nlohmann::ordered_json& rows) {
  std::vector<std::string> columns;
  std::set<std::string> seen;
  for (const auto& r : rows)
    for (const auto& [k, v] : r.items())
      if (seen.insert(k).second) columns.push_back(k);
  std::string out;
  for (std::size_t c = 0; c < columns.size(); ++c) {
    if (c) out += ',';
    out += csv_cell(columns[c]);
  }
  out += '\n';
  for (const auto& r : rows) {
    for (std::size_t c = 0; c < columns.size(); ++c) {
      if (c) out += ',';
      if (r.contains(columns[c])) out += csv_cell(r[columns[c]]);
    }
    out += '\n';
  }
  return out;
}

int run_sweep(const std::string& path, const SweepSpec& spec, const SweepOptions& options) {
  const SourceText src = SourceText::load(path);
  const auto combos = sweep_points(spec);
  std::vector<Point> points(combos.size());
  std::deque<Frontend> frontends;  // in place: a Frontend does not move (sys.model)

  // Every point derived first, so that a value the model refuses stops the sweep before
  // anything runs, with the point named.
  for (std::size_t i = 0; i < points.size(); ++i) {
    Point& p = points[i];
    p.sets = combos[i];
    p.label = sweep_label(i, points.size(), p.sets);
    FrontendOptions fo;
    fo.target = options.target;
    fo.sets = spec.fixed;
    fo.sets.insert(fo.sets.end(), p.sets.begin(), p.sets.end());
    fo.watchdog = true;
    try {
      const Frontend& fe = frontends.emplace_back(src, fo);
      check_runnable(fe);
      if (i == 0) fe.print_warnings(std::cerr);
      p.fe = &fe;
    } catch (const Error&) {
      std::cerr << "hybgen: sweep point " << p.label << ":\n";
      throw;
    }
  }
  const Model& m0 = points.front().fe->model;
  const std::string out =
      options.run.out.empty() ? default_out_dir(*points.front().fe, "-sweep") : options.run.out;
  OutputTransaction tx(out, OutputKind::Sweep);

  // One runner for every point: its sources are emitted with the file's parameter values
  // (build_model_runner), and every --set a point makes is read from its configuration.
  const BuildResult runner =
      build_model_runner(*points.front().fe, options.run.build, options.run.quiet);

  const std::size_t cores = std::max(1u, std::thread::hardware_concurrency());
  const std::size_t jobs =
      std::min({options.jobs ? options.jobs : cores, points.size(), kMaxChildren});
  const Environment env{
      {"OMP_NUM_THREADS", std::to_string(std::max<std::size_t>(1, cores / jobs))}};
  if (!options.run.quiet)
    std::cerr << "hybgen: sweep of " << points.size() << " points, " << jobs
              << " runner(s) at a time, into '" << out << "'\n";

  const InterruptGuard interrupt_guard;
  const fs::path staging = tx.stage();
  for (auto& p : points) {
    const fs::path dir = staging / p.label;
    std::error_code ec;
    fs::create_directory(dir, ec);
    if (ec) throw UsageError("cannot create '" + dir.string() + "': " + ec.message());
    nlohmann::json cfg = run_config(p.fe->model, dir.string(), out + "/" + p.label, true);
    cfg["label"] = p.label;  // its warnings say which point they are about
    cfg["provenance"] = run_provenance(*p.fe);
    cfg["seconds"] = {{"derive", p.fe->seconds}, {"build", runner.seconds}};
    p.config = (dir / "config.json").string();
    write_file_atomic(p.config, hybgen::rt::json_file_text(cfg));
  }

  // Run `jobs` at a time; each line of progress says which point ended how. Whatever ends
  // this scope early (an exception) stops and reaps the runners still running.
  struct Running {
    std::map<pid_t, std::size_t> pids;
    ~Running() {
      std::vector<pid_t> left;
      for (const auto& [pid, point] : pids) left.push_back(pid);
      stop_processes(left);
    }
  } running;
  std::size_t next = 0, done = 0;
  while (done < points.size()) {
    while (running.pids.size() < jobs && next < points.size()) {
      const pid_t pid = start_process(runner_command(points[next].fe->model.sim.settings,
                                                     runner.executable, points[next].config),
                                      interrupt_guard, env);
      if (pid < 0) break;  // interrupted: start nothing more
      running.pids[pid] = next++;
    }
    if (running.pids.empty()) break;
    const auto [pid, rc] = wait_process();
    const auto it = running.pids.find(pid);
    if (it == running.pids.end()) continue;  // not one of ours
    Point& p = points[it->second];
    running.pids.erase(it);
    p.rc = rc;
    ++done;
    if (interrupt_signal()) break;
    const std::string note = rc == 0 ? finish_point(p, staging / p.label) : "";
    if (!options.run.quiet)
      std::cerr << "hybgen: [" << done << "/" << points.size() << "] " << p.label << ": "
                << (p.rc == 0 ? "ok" + note : "failed (exit " + std::to_string(p.rc) + ")") << "\n";
  }
  if (interrupt_signal()) {
    while (!running.pids.empty()) running.pids.erase(wait_process().first);  // signalled too
    stop_if_interrupted(tx);
  }

  // The table, from each point's summary.json; a failed point's directory goes (half-written).
  nlohmann::ordered_json rows = nlohmann::ordered_json::array();
  int first_failure = 0;
  std::size_t failed = 0;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const Point& p = points[i];
    nlohmann::ordered_json row = {{"point", i}, {"dir", p.label}};
    for (const auto& kv : p.sets) {
      const auto eq = kv.find('=');
      row[kv.substr(0, eq)] = table_value(kv.substr(eq + 1));
    }
    row["status"] = p.rc == 0 ? "ok" : "failed";
    row["exit"] = p.rc;
    const int rc = p.rc;
    if (rc == 0) {
      // The runner's config, rewritten for OUT as `hybgen run` does.
      nlohmann::json cfg = nlohmann::json::parse(read_file(p.config));
      cfg["out_dir"] = out + "/" + p.label;
      write_file_atomic(p.config, hybgen::rt::json_file_text(cfg));
      // A summary quantity named like a swept key keeps both: the summary's as run_KEY.
      const nlohmann::ordered_json quantities = sweep_row(p.summary);
      for (const auto& [k, v] : quantities.items()) row[row.contains(k) ? "run_" + k : k] = v;
    }
    if (rc != 0) {
      ++failed;
      if (!first_failure) first_failure = rc;
      std::error_code ec;
      fs::remove_all(staging / p.label, ec);
    }
    rows.push_back(row);
  }
  if (failed == points.size()) {
    std::cerr << "hybgen: every point of the sweep failed; " << tx.unchanged() << "\n";
    return first_failure;
  }
  nlohmann::ordered_json axes = nlohmann::ordered_json::array();
  for (const auto& a : spec.axes) {
    nlohmann::ordered_json values = nlohmann::ordered_json::array();
    for (const auto& v : a.values) values.push_back(table_value(v));
    axes.push_back({{"key", a.key}, {"values", values}});
  }
  const nlohmann::ordered_json table = {
      {"model", m0.name}, {"fixed", spec.fixed}, {"axes", axes}, {"rows", rows}};
  write_file_atomic((staging / "sweep.json").string(), hybgen::rt::json_file_text(table));
  write_file_atomic((staging / "sweep.csv").string(), sweep_csv(rows));
  stop_if_interrupted(tx);  // asked to stop after the last runner: no swap
  tx.commit();
  if (!options.run.quiet || failed)
    std::cerr << "hybgen: sweep of " << points.size() << " points: " << points.size() - failed
              << " ran"
              << (failed ? ", " + std::to_string(failed) + " failed (their rows say so)"
                         : std::string())
              << "; table in " << out << "/sweep.csv and sweep.json\n";
  return first_failure;
}

}  // namespace hybgen::gen
