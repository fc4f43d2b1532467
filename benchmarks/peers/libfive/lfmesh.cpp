// lfmesh: mesh a .vm model (fidget's SSA text format) with libfive's Mesh::render.
//
// usage: lfmesh MODEL.vm XLO YLO ZLO XHI YHI ZHI CELLS WORKERS OUT [MAX_ERR]
//
// .vm format: one instruction per line, `NAME OP ARG...`, `#` starts a comment, the last instruction is
// the output (F < 0 inside).  Ops: var-x var-y var-z const add sub mul div neg square sqrt min max exp ln
// (alias log) sin cos tan asin acos atan atan2 abs, plus these extensions (not fidget's):
//   recip a         1/a
//   compare a b     -1 / 0 / 1 (libfive OP_COMPARE)
//   pow a n         a^n, n a const integer (libfive OP_POW)
//   nth-root a n    a^(1/n), n a const integer (libfive OP_NTH_ROOT)
//   mod a b         libfive OP_MOD
//
// Settings: min_feature = one cell ((hi - lo) / CELLS, times 1 + 1e-4 so that libfive's
// ceil(log2(size / min_feature)) gives exactly log2(CELLS) levels), max_err = MAX_ERR (default 1e-8),
// alg = DUAL_CONTOURING, workers = WORKERS.
//
// Output file (little endian):  "LFMESH01" (8 bytes), uint64 V, uint64 F, V*3 float64 vertices (converted
// from libfive's float32), F*3 int32 triangle indices (0-based).  libfive's reserved vertex 0 is dropped.
// stdout: one JSON line {"seconds", "cpu_seconds", "triangles", "vertices", "level", "instructions",
// "peak_rss_mib"} (peak_rss_mib: VmHWM right after Mesh::render, i.e. the process peak up to then).
// Only Mesh::render is timed (includes libfive's tree optimisation and Evaluator construction per worker).

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <fstream>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include "libfive/tree/tree.hpp"
#include "libfive/render/brep/mesh.hpp"
#include "libfive/render/brep/region.hpp"
#include "libfive/render/brep/settings.hpp"

using libfive::Tree;
namespace Op = libfive::Opcode;

static Tree read_vm(const std::string& path, size_t* count)
{
    std::ifstream in(path);
    if (!in) throw std::runtime_error("cannot open " + path);
    std::unordered_map<std::string, Tree> names;
    static const std::unordered_map<std::string, Op::Opcode> unary = {
        {"neg", Op::OP_NEG}, {"square", Op::OP_SQUARE}, {"sqrt", Op::OP_SQRT}, {"exp", Op::OP_EXP},
        {"ln", Op::OP_LOG}, {"log", Op::OP_LOG}, {"sin", Op::OP_SIN}, {"cos", Op::OP_COS},
        {"tan", Op::OP_TAN}, {"asin", Op::OP_ASIN}, {"acos", Op::OP_ACOS}, {"atan", Op::OP_ATAN},
        {"abs", Op::OP_ABS}, {"recip", Op::OP_RECIP}};
    static const std::unordered_map<std::string, Op::Opcode> binary = {
        {"add", Op::OP_ADD}, {"sub", Op::OP_SUB}, {"mul", Op::OP_MUL}, {"div", Op::OP_DIV},
        {"min", Op::OP_MIN}, {"max", Op::OP_MAX}, {"atan2", Op::OP_ATAN2}, {"compare", Op::OP_COMPARE},
        {"mod", Op::OP_MOD}, {"pow", Op::OP_POW}, {"nth-root", Op::OP_NTH_ROOT}};
    std::string line, last;
    size_t lineno = 0;
    *count = 0;
    while (std::getline(in, line)) {
        ++lineno;
        auto hash = line.find('#');
        if (hash != std::string::npos) line.resize(hash);
        std::istringstream ss(line);
        std::vector<std::string> w;
        for (std::string t; ss >> t;) w.push_back(t);
        if (w.empty()) continue;
        auto fail = [&](const std::string& why) {
            return std::runtime_error(path + ":" + std::to_string(lineno) + ": " + why);
        };
        if (w.size() < 2) throw fail("expected NAME OP ARG...");
        const std::string& op = w[1];
        auto arg = [&](size_t i) -> const Tree& {
            auto it = names.find(w[i]);
            if (it == names.end()) throw fail("undefined '" + w[i] + "'");
            return it->second;
        };
        auto arity = [&](size_t n) {
            if (w.size() != n + 2) throw fail(op + " takes " + std::to_string(n) + " arguments");
        };
        Tree t = Tree::invalid();
        if (op == "var-x") { arity(0); t = Tree::X(); }
        else if (op == "var-y") { arity(0); t = Tree::Y(); }
        else if (op == "var-z") { arity(0); t = Tree::Z(); }
        else if (op == "const") { arity(1); t = Tree(std::strtod(w[2].c_str(), nullptr)); }
        else if (unary.count(op)) { arity(1); t = Tree::unary(unary.at(op), arg(2)); }
        else if (binary.count(op)) { arity(2); t = Tree::binary(binary.at(op), arg(2), arg(3)); }
        else throw fail("unknown op '" + op + "'");
        if (names.count(w[0])) throw fail("'" + w[0] + "' defined twice");
        names.emplace(w[0], t);
        last = w[0];
        ++*count;
    }
    if (last.empty()) throw std::runtime_error(path + ": no instructions");
    return names.at(last);
}

// Peak resident set of this process image (VmHWM of /proc/self/status, MiB).  Unlike getrusage's ru_maxrss,
// it does not include the RSS of a (v)forking parent before exec.
static double peak_rss_mib()
{
    std::ifstream st("/proc/self/status");
    std::string line;
    while (std::getline(st, line))
        if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
    return -1;
}

static double cpu_now()
{
    timespec ts;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
    return ts.tv_sec + 1e-9 * ts.tv_nsec;
}

int main(int argc, char** argv)
{
    if (argc != 11 && argc != 12) {
        std::cerr << "usage: " << argv[0]
                  << " MODEL.vm XLO YLO ZLO XHI YHI ZHI CELLS WORKERS OUT [MAX_ERR]\n";
        return 2;
    }
    try {
        size_t count = 0;
        Tree tree = read_vm(argv[1], &count);
        libfive::Region<3>::Pt lo(std::atof(argv[2]), std::atof(argv[3]), std::atof(argv[4]));
        libfive::Region<3>::Pt hi(std::atof(argv[5]), std::atof(argv[6]), std::atof(argv[7]));
        const long cells = std::atol(argv[8]);
        const unsigned workers = std::atoi(argv[9]);
        const std::string out = argv[10];
        if (cells < 1 || workers < 1) throw std::runtime_error("CELLS and WORKERS must be >= 1");

        libfive::Region<3> region(lo, hi);
        libfive::BRepSettings settings;
        settings.min_feature = (hi - lo).minCoeff() / double(cells) * (1 + 1e-4);
        settings.max_err = argc == 12 ? std::atof(argv[11]) : 1e-8;
        settings.alg = libfive::DUAL_CONTOURING;
        settings.workers = workers;
        const int level = region.withResolution(settings.min_feature).level;

        const double c0 = cpu_now();
        const auto t0 = std::chrono::steady_clock::now();
        auto mesh = libfive::Mesh::render(tree, region, settings);
        const auto t1 = std::chrono::steady_clock::now();
        const double c1 = cpu_now();
        if (!mesh) throw std::runtime_error("Mesh::render returned nullptr");
        const double rss = peak_rss_mib();

        const uint64_t V = mesh->verts.size() - 1, F = mesh->branes.size();
        std::ofstream f(out, std::ios::binary);
        if (!f) throw std::runtime_error("cannot write " + out);
        f.write("LFMESH01", 8);
        f.write(reinterpret_cast<const char*>(&V), 8);
        f.write(reinterpret_cast<const char*>(&F), 8);
        std::vector<double> vbuf(3 * V);
        for (uint64_t i = 0; i < V; ++i)
            for (int k = 0; k < 3; ++k) vbuf[3 * i + k] = mesh->verts[i + 1][k];
        f.write(reinterpret_cast<const char*>(vbuf.data()), vbuf.size() * sizeof(double));
        std::vector<int32_t> tbuf(3 * F);
        for (uint64_t i = 0; i < F; ++i)
            for (int k = 0; k < 3; ++k) {
                const uint32_t j = mesh->branes[i][k];
                if (j == 0 || j > V) throw std::runtime_error("bad triangle index");
                tbuf[3 * i + k] = int32_t(j - 1);
            }
        f.write(reinterpret_cast<const char*>(tbuf.data()), tbuf.size() * sizeof(int32_t));
        if (!f) throw std::runtime_error("write failed: " + out);

        std::printf("{\"seconds\": %.6f, \"cpu_seconds\": %.6f, \"triangles\": %llu, \"vertices\": %llu, "
                    "\"level\": %d, \"instructions\": %zu, \"peak_rss_mib\": %.1f}\n",
                    std::chrono::duration<double>(t1 - t0).count(), c1 - c0,
                    (unsigned long long)F, (unsigned long long)V, level, count, rss);
    } catch (const std::exception& e) {
        std::cerr << "lfmesh: " << e.what() << "\n";
        return 1;
    }
    return 0;
}
