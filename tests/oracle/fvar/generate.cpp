// generate: OpenSubdiv's face-varying (UV) results for subtrace's tests. A test-data tool,
// never part of subtrace; build.sh beside it compiles it against the system's OpenSubdiv
// (Debian's libosd-dev) and packs its output into one .npz per shape.
//
//     generate SHAPE.obj catmark|loop OUTDIR [STRIDE] [LEVELS]
//
// Reads the OBJ's v, vt and f lines (every corner must name a vt) and OpenSubdiv's `t` tags
// (crease, corner, hole, interpolateboundary, creasemethod, smoothtriangles, as
// regression/common/far_utils.h applies them: boundary edge-only, uniform creases and the
// Catmark triangle rule when absent; a facevaryinginterpolateboundary tag is not read, every
// mode is computed). Then, for each Sdc::Options::FVarLinearInterpolation mode k = 0..5
// (NONE, CORNERS_ONLY, CORNERS_PLUS1, CORNERS_PLUS2, BOUNDARIES, ALL), in double precision:
//
//   * uniform refinement to LEVELS (default 2) with PrimvarRefinerReal<double>::
//     InterpolateFaceVarying: the UV of every face corner of levels 1..LEVELS, faces in
//     Far's order (refined<L>_m<k>, (corners, 2));
//   * Far::PatchTable with a face-varying channel (generateFVarLegacyLinearPatches off, so
//     the channel gets its own smooth patches and RefineAdaptive isolates its features too;
//     Gregory end caps, infinitely sharp patches, no legacy sharp corners) at isolation
//     levels 10 and 8: every sample point (ptex face, u, v) through Far::PatchMap and
//     EvaluateBasisFaceVarying (uv_m<k>, (m, 2), at level 10), whether its face-varying
//     patch at level 10 is a regular one (B-spline, box spline or linear: exact) or an end
//     cap (regular_m<k>), and the change of the value between levels 10 and 8 (isodiff_m<k>).
//
// Samples (the same for every mode; sample_kind): 0 256 random points over the ptex faces of
// non-hole faces (std::mt19937_64 seed 12345, the top 53 bits as a double; Loop: folded
// into u + v <= 1); on every STRIDE-th of those ptex faces (default 1): 1 its corners,
// 2 its centre, 4 one random point on each side, and 3 points at corner-local offsets
// (s, s/2), s = 2^-3, 2^-6, 3 * 2^-10, at each corner where some mode's face-varying patch
// at level 10 is an end cap.
//
// OUTDIR gets one .npy per array and meta.json.

#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTable.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>
#include <opensubdiv/far/stencilTable.h>
#include <opensubdiv/far/topologyDescriptor.h>
#include <opensubdiv/version.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <memory>
#include <random>
#include <sstream>
#include <string>
#include <vector>

using namespace OpenSubdiv;

static void fail(std::string const &what) {
    std::fprintf(stderr, "generate: %s\n", what.c_str());
    std::exit(2);
}

// ---------------------------------------------------------------------------------------
// .npy output

static void write_npy(std::string const &path, char const *descr, std::vector<size_t> shape,
                      void const *data, size_t bytes) {
    std::ostringstream dict;
    dict << "{'descr': '" << descr << "', 'fortran_order': False, 'shape': (";
    for (size_t i = 0; i < shape.size(); ++i) dict << shape[i] << (shape.size() == 1 ? "," : (i + 1 < shape.size() ? ", " : ""));
    dict << "), }";
    std::string header = dict.str();
    size_t total = 10 + header.size() + 1;
    header.append((64 - total % 64) % 64, ' ');
    header.push_back('\n');
    std::ofstream out(path, std::ios::binary);
    if (!out) fail("cannot write " + path);
    out.write("\x93NUMPY\x01\x00", 8);
    uint16_t n = (uint16_t)header.size();
    out.write(reinterpret_cast<char const *>(&n), 2);
    out.write(header.data(), header.size());
    out.write(static_cast<char const *>(data), bytes);
}

static void save(std::string const &dir, std::string const &name, std::vector<double> const &v,
                 size_t cols) {
    write_npy(dir + "/" + name + ".npy", "<f8", cols == 1 ? std::vector<size_t>{v.size()}
                                                         : std::vector<size_t>{v.size() / cols, cols},
              v.data(), v.size() * sizeof(double));
}

static void save(std::string const &dir, std::string const &name, std::vector<int32_t> const &v) {
    write_npy(dir + "/" + name + ".npy", "<i4", {v.size()}, v.data(), v.size() * sizeof(int32_t));
}

static void save(std::string const &dir, std::string const &name, std::vector<uint8_t> const &v) {
    write_npy(dir + "/" + name + ".npy", "|u1", {v.size()}, v.data(), v.size());
}

// ---------------------------------------------------------------------------------------
// the OBJ cage

struct Cage {
    std::vector<double> points, uvs;              // (V,3), (T,2)
    std::vector<int> sizes, verts, fvar;          // faces and their corners' vt indices
    std::vector<int> creasePairs, corners, holes;
    std::vector<float> creaseWeights, cornerWeights;
    Sdc::Options options;
};

static int obj_index(std::string const &token, int count, int line) {
    int i = std::atoi(token.c_str());
    if (i == 0) fail("line " + std::to_string(line) + ": index 0 in '" + token + "'");
    return i < 0 ? count + i : i - 1;
}

static Cage read_obj(std::string const &path) {
    std::ifstream in(path);
    if (!in) fail("cannot read " + path);
    Cage c;
    c.options.SetVtxBoundaryInterpolation(Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    c.options.SetCreasingMethod(Sdc::Options::CREASE_UNIFORM);
    c.options.SetTriangleSubdivision(Sdc::Options::TRI_SUB_CATMARK);
    std::string text;
    int line = 0;
    while (std::getline(in, text)) {
        ++line;
        size_t hash = text.find('#');
        if (hash != std::string::npos) text.resize(hash);
        std::istringstream s(text);
        std::string key;
        if (!(s >> key)) continue;
        if (key == "v") {
            // re-read in double precision with strtod (as the vertex oracle does)
            std::string x, y, z;
            s >> x >> y >> z;
            c.points.push_back(std::strtod(x.c_str(), nullptr));
            c.points.push_back(std::strtod(y.c_str(), nullptr));
            c.points.push_back(std::strtod(z.c_str(), nullptr));
        } else if (key == "vt") {
            std::string u, v = "0";
            s >> u >> v;
            c.uvs.push_back(std::strtod(u.c_str(), nullptr));
            c.uvs.push_back(std::strtod(v.c_str(), nullptr));
        } else if (key == "f") {
            std::string corner;
            int n = 0;
            while (s >> corner) {
                size_t a = corner.find('/');
                if (a == std::string::npos || a + 1 >= corner.size() || corner[a + 1] == '/')
                    fail("line " + std::to_string(line) + ": a corner without vt");
                size_t b = corner.find('/', a + 1);
                c.verts.push_back(obj_index(corner.substr(0, a), (int)c.points.size() / 3, line));
                c.fvar.push_back(obj_index(corner.substr(a + 1, b == std::string::npos ? b : b - a - 1),
                                           (int)c.uvs.size() / 2, line));
                ++n;
            }
            c.sizes.push_back(n);
        } else if (key == "t") {
            std::string name, counts;
            s >> name >> counts;
            int ni = 0, nf = 0, ns = 0;
            if (std::sscanf(counts.c_str(), "%d/%d/%d", &ni, &nf, &ns) != 3)
                fail("line " + std::to_string(line) + ": bad tag header");
            std::vector<int> ints(ni);
            std::vector<float> floats(nf);
            std::vector<std::string> strings(ns);
            for (int &i : ints) s >> i;
            for (float &f : floats) s >> f;
            for (std::string &t : strings) s >> t;
            if (name == "crease") {
                for (int k = 0; k + 1 < ni; k += 2) {
                    c.creasePairs.push_back(ints[k]);
                    c.creasePairs.push_back(ints[k + 1]);
                    c.creaseWeights.push_back(floats[nf == 1 ? 0 : k / 2]);
                }
            } else if (name == "corner") {
                for (int k = 0; k < ni; ++k) {
                    c.corners.push_back(ints[k]);
                    c.cornerWeights.push_back(floats[nf == 1 ? 0 : k]);
                }
            } else if (name == "hole") {
                c.holes.insert(c.holes.end(), ints.begin(), ints.end());
            } else if (name == "interpolateboundary") {
                static const Sdc::Options::VtxBoundaryInterpolation modes[3] = {
                    Sdc::Options::VTX_BOUNDARY_NONE, Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER,
                    Sdc::Options::VTX_BOUNDARY_EDGE_ONLY};
                if (ni != 1 || ints[0] < 0 || ints[0] > 2) fail("bad interpolateboundary tag");
                c.options.SetVtxBoundaryInterpolation(modes[ints[0]]);
            } else if (name == "creasemethod") {
                if (ns != 1 || (strings[0] != "normal" && strings[0] != "chaikin"))
                    fail("bad creasemethod tag");
                c.options.SetCreasingMethod(strings[0] == "chaikin" ? Sdc::Options::CREASE_CHAIKIN
                                                                    : Sdc::Options::CREASE_UNIFORM);
            } else if (name == "smoothtriangles") {
                if (ns != 1 || (strings[0] != "catmark" && strings[0] != "smooth"))
                    fail("bad smoothtriangles tag");
                c.options.SetTriangleSubdivision(strings[0] == "smooth" ? Sdc::Options::TRI_SUB_SMOOTH
                                                                        : Sdc::Options::TRI_SUB_CATMARK);
            } else if (name != "facevaryinginterpolateboundary") {
                fail("unknown tag " + name);
            }
        }
    }
    if (c.sizes.empty()) fail(path + ": no faces");
    return c;
}

static Far::TopologyRefiner *make_refiner(Cage const &c, Sdc::SchemeType scheme, int mode) {
    Far::TopologyDescriptor d;
    d.numVertices = (int)c.points.size() / 3;
    d.numFaces = (int)c.sizes.size();
    d.numVertsPerFace = c.sizes.data();
    d.vertIndicesPerFace = c.verts.data();
    d.numCreases = (int)c.creaseWeights.size();
    d.creaseVertexIndexPairs = c.creasePairs.data();
    d.creaseWeights = c.creaseWeights.data();
    d.numCorners = (int)c.cornerWeights.size();
    d.cornerVertexIndices = c.corners.data();
    d.cornerWeights = c.cornerWeights.data();
    d.numHoles = (int)c.holes.size();
    d.holeIndices = c.holes.data();
    d.isLeftHanded = false;
    Far::TopologyDescriptor::FVarChannel channel;
    channel.numValues = (int)c.uvs.size() / 2;
    channel.valueIndices = c.fvar.data();
    d.numFVarChannels = 1;
    d.fvarChannels = &channel;
    Sdc::Options options = c.options;
    options.SetFVarLinearInterpolation((Sdc::Options::FVarLinearInterpolation)mode);
    typedef Far::TopologyRefinerFactory<Far::TopologyDescriptor> Factory;
    Far::TopologyRefiner *r = Factory::Create(d, Factory::Options(scheme, options));
    if (!r) fail("OpenSubdiv rejected the topology");
    return r;
}

// ---------------------------------------------------------------------------------------
// values

struct UV {
    double p[2];
    void Clear() { p[0] = p[1] = 0.0; }
    void AddWithWeight(UV const &src, double w) {
        p[0] += w * src.p[0];
        p[1] += w * src.p[1];
    }
};

// The face-varying patch table of one mode at one isolation level, with its values.
struct Evaluator {
    std::unique_ptr<Far::PatchTable> table;
    std::unique_ptr<Far::PatchMap> map;
    std::vector<UV> values;  // base, refined levels, then the end caps' local points

    Evaluator(Cage const &c, Sdc::SchemeType scheme, int mode, int isolation) {
        std::unique_ptr<Far::TopologyRefiner> refiner(make_refiner(c, scheme, mode));
        Far::PatchTableFactory::Options po(isolation);
        po.SetPatchPrecision<double>();
        po.SetFVarPatchPrecision<double>();
        po.useInfSharpPatch = true;
        po.useSingleCreasePatch = false;
        po.generateLegacySharpCornerPatches = false;
        po.generateVaryingTables = false;
        po.endCapType = Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS;
        po.generateFVarTables = true;
        po.generateFVarLegacyLinearPatches = false;
        int fvarChannel = 0;
        po.numFVarChannels = 1;
        po.fvarChannelIndices = &fvarChannel;
        refiner->RefineAdaptive(po.GetRefineAdaptiveOptions());
        table.reset(Far::PatchTableFactory::Create(*refiner, po));
        map.reset(new Far::PatchMap(*table));
        int nBase = refiner->GetLevel(0).GetNumFVarValues(0);
        int nTotal = refiner->GetNumFVarValuesTotal(0);
        int nLocal = table->GetNumLocalPointsFaceVarying(0);
        values.resize(nTotal + nLocal);
        for (int i = 0; i < nBase; ++i) {
            values[i].p[0] = c.uvs[2 * i];
            values[i].p[1] = c.uvs[2 * i + 1];
        }
        Far::PrimvarRefinerReal<double> primvar(*refiner);
        UV *src = values.data();
        for (int level = 1; level < refiner->GetNumLevels(); ++level) {
            UV *dst = src + refiner->GetLevel(level - 1).GetNumFVarValues(0);
            primvar.InterpolateFaceVarying(level, src, dst, 0);
            src = dst;
        }
        if (nLocal) {
            Far::StencilTableReal<double> const *st = table->GetLocalPointFaceVaryingStencilTable<double>(0);
            st->UpdateValues(values.data(), values.data() + nTotal);
        }
    }

    // the value at (ptex, u, v); regular: whether the face-varying patch there is regular
    void eval(int ptex, double u, double v, double out[2], bool &regular) const {
        Far::PatchTable::PatchHandle const *h = map->FindPatch(ptex, u, v);
        if (!h) fail("no patch at a sample (ptex " + std::to_string(ptex) + ")");
        double w[20];
        table->EvaluateBasisFaceVarying<double>(*h, u, v, w, 0, 0, 0, 0, 0, 0);
        Far::ConstIndexArray cv = table->GetPatchFVarValues(*h, 0);
        out[0] = out[1] = 0.0;
        for (int i = 0; i < cv.size(); ++i) {
            out[0] += w[i] * values[cv[i]].p[0];
            out[1] += w[i] * values[cv[i]].p[1];
        }
        regular = table->GetPatchFVarPatchParam(*h, 0).IsRegular();
    }
};

static double uniform01(std::mt19937_64 &rng) { return (double)(rng() >> 11) * (1.0 / 9007199254740992.0); }

int main(int argc, char **argv) {
    if (argc < 4) fail("usage: generate SHAPE.obj catmark|loop OUTDIR [STRIDE] [LEVELS]");
    std::string path = argv[1], schemeName = argv[2], out = argv[3];
    int stride = argc > 4 ? std::atoi(argv[4]) : 1;
    int levels = argc > 5 ? std::atoi(argv[5]) : 2;
    if (schemeName != "catmark" && schemeName != "loop") fail("scheme must be catmark or loop");
    bool loop = schemeName == "loop";
    Sdc::SchemeType scheme = loop ? Sdc::SCHEME_LOOP : Sdc::SCHEME_CATMARK;
    Cage cage = read_obj(path);
    int nValues = (int)cage.uvs.size() / 2;
    for (int i : cage.fvar)
        if (i < 0 || i >= nValues) fail("a vt index is out of range");

    // ptex faces of non-hole faces
    std::unique_ptr<Far::TopologyRefiner> base(make_refiner(cage, scheme, 0));
    Far::PtexIndices ptex(*base);
    int regSize = loop ? 3 : 4;
    std::vector<int> live;
    std::vector<int> corners;  // corners of each ptex face (3 for Loop, else 4)
    for (int f = 0; f < (int)cage.sizes.size(); ++f) {
        int n = cage.sizes[f] == regSize ? 1 : cage.sizes[f];
        if (base->GetLevel(0).IsFaceHole(f)) continue;
        for (int k = 0; k < n; ++k) live.push_back(ptex.GetFaceId(f) + k);
    }
    int nc = loop ? 3 : 4;
    static const double quad[4][2] = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
    static const double tri[3][2] = {{0, 0}, {1, 0}, {0, 1}};
    auto corner = [&](int j, int k) { return loop ? tri[j][k] : quad[j][k]; };

    std::vector<int32_t> sPtex, sKind;
    std::vector<double> sUV;
    auto add = [&](int p, double u, double v, int kind) {
        sPtex.push_back(p);
        sUV.push_back(u);
        sUV.push_back(v);
        sKind.push_back(kind);
    };
    std::mt19937_64 rng(12345);
    for (int i = 0; i < 256; ++i) {
        int p = live[(size_t)(uniform01(rng) * live.size())];
        double u = uniform01(rng), v = uniform01(rng);
        if (loop && u + v > 1.0) { u = 1.0 - u; v = 1.0 - v; }
        add(p, u, v, 0);
    }
    std::vector<int> chosen;
    for (size_t i = 0; i < live.size(); i += stride) chosen.push_back(live[i]);
    for (int p : chosen)
        for (int j = 0; j < nc; ++j) add(p, corner(j, 0), corner(j, 1), 1);
    for (int p : chosen) add(p, loop ? 1.0 / 3.0 : 0.5, loop ? 1.0 / 3.0 : 0.5, 2);
    for (int p : chosen)
        for (int j = 0; j < nc; ++j) {
            double t = uniform01(rng);
            double a0 = corner(j, 0), a1 = corner(j, 1);
            double b0 = corner((j + 1) % nc, 0), b1 = corner((j + 1) % nc, 1);
            add(p, a0 + t * (b0 - a0), a1 + t * (b1 - a1), 4);
        }

    // the modes' patch tables, and the corners where one of them has an end cap
    std::vector<std::unique_ptr<Evaluator>> fine, coarse;
    for (int mode = 0; mode < 6; ++mode) {
        fine.emplace_back(new Evaluator(cage, scheme, mode, 10));
        coarse.emplace_back(new Evaluator(cage, scheme, mode, 8));
    }
    const double offsets[3] = {1.0 / 8.0, 1.0 / 64.0, 3.0 / 1024.0};
    for (int p : chosen)
        for (int j = 0; j < nc; ++j) {
            bool irregular = false;
            for (int mode = 0; mode < 6; ++mode) {
                double uv[2];
                bool regular;
                fine[mode]->eval(p, corner(j, 0), corner(j, 1), uv, regular);
                irregular |= !regular;
            }
            if (!irregular) continue;
            int jn = (j + 1) % nc, jp = (j + nc - 1) % nc;
            for (double s : offsets) {
                double u = corner(j, 0) + s * (corner(jn, 0) - corner(j, 0)) + 0.5 * s * (corner(jp, 0) - corner(j, 0));
                double v = corner(j, 1) + s * (corner(jn, 1) - corner(j, 1)) + 0.5 * s * (corner(jp, 1) - corner(j, 1));
                add(p, u, v, 3);
            }
        }
    size_t m = sPtex.size();
    save(out, "sample_ptex_face", sPtex);
    save(out, "sample_kind", sKind);
    save(out, "sample_uv", sUV, 2);

    for (int mode = 0; mode < 6; ++mode) {
        std::string tag = "_m" + std::to_string(mode);
        std::vector<double> uv(2 * m);
        std::vector<double> isodiff(m);
        std::vector<uint8_t> regular(m);
        for (size_t i = 0; i < m; ++i) {
            bool reg, reg8;
            double c8[2];
            fine[mode]->eval(sPtex[i], sUV[2 * i], sUV[2 * i + 1], &uv[2 * i], reg);
            coarse[mode]->eval(sPtex[i], sUV[2 * i], sUV[2 * i + 1], c8, reg8);
            regular[i] = reg;
            isodiff[i] = std::fmax(std::fabs(uv[2 * i] - c8[0]), std::fabs(uv[2 * i + 1] - c8[1]));
        }
        save(out, "uv" + tag, uv, 2);
        save(out, "regular" + tag, regular);
        save(out, "isodiff" + tag, isodiff, 1);

        // uniform refinement: every face corner's value, level by level
        std::unique_ptr<Far::TopologyRefiner> r(make_refiner(cage, scheme, mode));
        Far::TopologyRefiner::UniformOptions uo(levels);
        uo.fullTopologyInLastLevel = true;
        r->RefineUniform(uo);
        std::vector<UV> values(r->GetNumFVarValuesTotal(0));
        for (int i = 0; i < nValues; ++i) {
            values[i].p[0] = cage.uvs[2 * i];
            values[i].p[1] = cage.uvs[2 * i + 1];
        }
        Far::PrimvarRefinerReal<double> primvar(*r);
        UV *src = values.data();
        for (int level = 1; level <= levels; ++level) {
            UV *dst = src + r->GetLevel(level - 1).GetNumFVarValues(0);
            primvar.InterpolateFaceVarying(level, src, dst, 0);
            Far::TopologyLevel const &lev = r->GetLevel(level);
            std::vector<double> corner_uv;
            for (int f = 0; f < lev.GetNumFaces(); ++f) {
                Far::ConstIndexArray fv = lev.GetFaceFVarValues(f, 0);
                for (int k = 0; k < fv.size(); ++k) {
                    corner_uv.push_back(dst[fv[k]].p[0]);
                    corner_uv.push_back(dst[fv[k]].p[1]);
                }
            }
            save(out, "refined" + std::to_string(level) + tag, corner_uv, 2);
            src = dst;
        }
    }

    std::ofstream meta(out + "/meta.json");
    meta << "{\"shape\": \"" << path.substr(path.find_last_of('/') + 1) << "\", \"scheme\": \""
         << schemeName << "\", \"opensubdiv\": \"" << OPENSUBDIV_VERSION_MAJOR << "."
         << OPENSUBDIV_VERSION_MINOR << "." << OPENSUBDIV_VERSION_PATCH
         << "\", \"isolation\": [10, 8], \"levels\": " << levels << ", \"stride\": " << stride
         << ", \"samples\": " << m
         << ", \"modes\": [\"none\", \"corners_only\", \"corners_plus1\", \"corners_plus2\", "
            "\"boundaries\", \"all\"]}\n";
    return 0;
}
