// Mesh adapter: OBJ (+ MTL) by a small parser of our own, PLY/OFF/STL through OpenMesh.
//
// Why OBJ is parsed here and not by OpenMesh: OpenMesh's OBJ reader builds a halfedge mesh, so it
// drops or duplicates non-manifold faces, re-indexes texcoords per halfedge (the file's vt index
// lists, and with them exact seams, are lost) and gives no per-face material names. The input's
// vertices, faces and corner UVs must stay exactly as stored (pipeline/geom/mesh.h).
#include "io.h"

// GCC 12 reports a false maybe-uninitialized inside OpenMesh's property templates.
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <OpenMesh/Core/IO/MeshIO.hh>
#include <OpenMesh/Core/Mesh/PolyMesh_ArrayKernelT.hh>
#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic pop
#endif

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <climits>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

extern "C" {
#include "../../runtime/log.h"
}

namespace {

// Counts beyond this are refused (keeps every index and byte size far from int overflow).
const size_t kMaxElements = 1u << 28;

std::string lower_ext(const char *path) {
    const char *dot = strrchr(path, '.');
    const char *slash = strrchr(path, '/');
    if (!dot || (slash && dot < slash)) return "";
    std::string e(dot + 1);
    for (char &c : e) c = (char)tolower((unsigned char)c);
    return e;
}

std::string dir_of(const char *path) {
    const char *slash = strrchr(path, '/');
    return slash ? std::string(path, (size_t)(slash - path) + 1) : std::string();
}

bool file_exists(const std::string &p) {
    FILE *f = fopen(p.c_str(), "rb");
    if (f) fclose(f);
    return f != nullptr;
}

int read_text_file(const char *path, std::string &text, mx_status *st) {
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    char buf[1 << 16];
    size_t n;
    while ((n = fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
    int bad = ferror(f);
    fclose(f);
    if (bad) return mx_fail(st, MX_EINPUT, "%s: read error", path);
    return 0;
}

void copy_name(char *dst, size_t cap, const std::string &s) { snprintf(dst, cap, "%s", s.c_str()); }

// Everything parsed from an OBJ, before conversion to mx_mesh.
struct ObjData {
    std::vector<float> pos, uv, nrm;
    std::vector<int32_t> tri, tri_uv, tri_nrm, tri_mat;
    std::vector<std::string> mat_names;
    std::vector<std::string> mtllibs;
    bool any_uv = false, any_nrm = false, used_default = false;
};

// One text line split into whitespace-separated tokens (views into the line buffer).
struct Tokens {
    std::vector<std::pair<const char *, size_t>> t;
    std::string str(size_t i) const { return std::string(t[i].first, t[i].second); }
};

void tokenize(const char *s, const char *end, Tokens &out) {
    out.t.clear();
    while (s < end) {
        while (s < end && (*s == ' ' || *s == '\t' || *s == '\r')) s++;
        const char *b = s;
        while (s < end && *s != ' ' && *s != '\t' && *s != '\r') s++;
        if (s > b) out.t.emplace_back(b, (size_t)(s - b));
    }
}

// The rest of a line after its keyword, trimmed (names and paths may contain spaces).
std::string rest_of_line(const char *s, const char *end, size_t keyword_len) {
    s += keyword_len;
    while (s < end && (*s == ' ' || *s == '\t')) s++;
    while (end > s && (end[-1] == ' ' || end[-1] == '\t' || end[-1] == '\r')) end--;
    return std::string(s, (size_t)(end - s));
}

bool parse_float(const std::pair<const char *, size_t> &tok, float *out) {
    char buf[64];
    if (tok.second >= sizeof buf) return false;
    memcpy(buf, tok.first, tok.second);
    buf[tok.second] = 0;
    char *e;
    *out = strtof(buf, &e);
    return e == buf + tok.second;
}

// Parses one OBJ index ("12", "-3") into a 0-based index given the current element count.
// Range checks against the final counts happen after parsing (forward references are legal).
bool parse_index(const char *s, size_t n, size_t count, long *out) {
    if (n == 0 || n > 12) return false;
    char buf[16];
    memcpy(buf, s, n);
    buf[n] = 0;
    char *e;
    long v = strtol(buf, &e, 10);
    if (e != buf + n || v == 0) return false;
    *out = v > 0 ? v - 1 : (long)count + v;
    return *out >= 0 && *out < INT_MAX;
}

// One face corner "v", "v/vt", "v//vn" or "v/vt/vn".
bool parse_corner(const std::pair<const char *, size_t> &tok, const ObjData &d, long c[3]) {
    const char *s = tok.first, *end = tok.first + tok.second;
    c[0] = c[1] = c[2] = -1;
    size_t counts[3] = {d.pos.size() / 3, d.uv.size() / 2, d.nrm.size() / 3};
    for (int k = 0; k < 3 && s <= end; k++) {
        const char *slash = (const char *)memchr(s, '/', (size_t)(end - s));
        const char *stop = slash ? slash : end;
        if (stop > s) {
            if (!parse_index(s, (size_t)(stop - s), counts[k], &c[k])) return false;
        } else if (k == 0) {
            return false;
        }
        if (!slash) break;
        s = slash + 1;
    }
    return true;
}

int current_material(ObjData &d, const std::string &name) {
    for (size_t i = 0; i < d.mat_names.size(); i++)
        if (d.mat_names[i] == name) return (int)i;
    d.mat_names.push_back(name);
    return (int)d.mat_names.size() - 1;
}

int add_face(ObjData &d, const Tokens &tk, int mat, const char *path, long line, mx_status *st) {
    size_t n = tk.t.size() - 1;
    if (n < 3) return mx_fail(st, MX_EINPUT, "%s:%ld: face with %zu corners", path, line, n);
    std::vector<long> c(3 * n);
    for (size_t i = 0; i < n; i++)
        if (!parse_corner(tk.t[i + 1], d, &c[3 * i]))
            return mx_fail(st, MX_EINPUT, "%s:%ld: bad face corner '%s'", path, line, tk.str(i + 1).c_str());
    for (size_t i = 0; i < n; i++) {
        if (c[3 * i + 1] >= 0) d.any_uv = true;
        if (c[3 * i + 2] >= 0) d.any_nrm = true;
    }
    if (d.tri.size() / 3 + n > kMaxElements)
        return mx_fail(st, MX_EINPUT, "%s:%ld: too many faces", path, line);
    // Fan triangulation (0, i, i+1): keeps the polygon's winding and the file's corner order.
    for (size_t i = 1; i + 1 < n; i++) {
        size_t corner[3] = {0, i, i + 1};
        for (size_t k : corner) {
            d.tri.push_back((int32_t)c[3 * k]);
            d.tri_uv.push_back((int32_t)c[3 * k + 1]);
            d.tri_nrm.push_back((int32_t)c[3 * k + 2]);
        }
        d.tri_mat.push_back(mat);
    }
    return 0;
}

int add_floats(std::vector<float> &v, const Tokens &tk, int need, int max, const char *path, long line,
               mx_status *st) {
    int n = (int)tk.t.size() - 1;
    if (n < need) return mx_fail(st, MX_EINPUT, "%s:%ld: '%s' needs %d numbers", path, line, tk.str(0).c_str(), need);
    if (v.size() / (size_t)max > kMaxElements) return mx_fail(st, MX_EINPUT, "%s:%ld: too many elements", path, line);
    for (int k = 0; k < max; k++) {
        float x = 0.f;
        if (k < n && !parse_float(tk.t[k + 1], &x))
            return mx_fail(st, MX_EINPUT, "%s:%ld: bad number '%s'", path, line, tk.str(k + 1).c_str());
        if (!std::isfinite(x))
            return mx_fail(st, MX_EINPUT, "%s:%ld: non-finite value '%s'", path, line, tk.str(k + 1).c_str());
        v.push_back(x);
    }
    return 0;
}

int parse_obj_text(const std::string &text, const char *path, ObjData &d, mx_status *st) {
    const char *p = text.data(), *end = p + text.size();
    Tokens tk;
    int mat = -1; // -1: faces before any usemtl (material "default", created when used)
    long line = 0;
    while (p < end) {
        const char *eol = (const char *)memchr(p, '\n', (size_t)(end - p));
        if (!eol) eol = end;
        line++;
        const char *hash = (const char *)memchr(p, '#', (size_t)(eol - p));
        const char *stop = hash ? hash : eol;
        tokenize(p, stop, tk);
        if (!tk.t.empty()) {
            std::string kw = tk.str(0);
            int rc = 0;
            if (kw == "v") rc = add_floats(d.pos, tk, 3, 3, path, line, st);
            else if (kw == "vt") rc = add_floats(d.uv, tk, 1, 2, path, line, st);
            else if (kw == "vn") rc = add_floats(d.nrm, tk, 3, 3, path, line, st);
            else if (kw == "f") {
                if (mat < 0) {
                    mat = current_material(d, "default");
                    d.used_default = true;
                }
                rc = add_face(d, tk, mat, path, line, st);
            } else if (kw == "usemtl") mat = current_material(d, rest_of_line(p, stop, 6));
            else if (kw == "mtllib") d.mtllibs.push_back(rest_of_line(p, stop, 6));
            if (rc) return -1;
        }
        p = eol + 1;
    }
    return 0;
}

// Reads the OBJ's mtllib files: (material name, map_Kd path) in file order. A missing .mtl
// is a warning.
void read_mtl_libraries(const char *obj_path, const ObjData &d,
                        std::vector<std::pair<std::string, std::string>> &mtls) {
    std::string dir = dir_of(obj_path);
    for (const std::string &lib : d.mtllibs) {
        std::string mtl_path = dir + lib, text;
        mx_status ignore;
        if (read_text_file(mtl_path.c_str(), text, &ignore)) {
            mx_warn("%s: material library %s not found; no textures", obj_path, mtl_path.c_str());
            continue;
        }
        std::string mtl_dir = dir_of(mtl_path.c_str());
        const char *p = text.data(), *end = p + text.size();
        Tokens tk;
        while (p < end) {
            const char *eol = (const char *)memchr(p, '\n', (size_t)(end - p));
            if (!eol) eol = end;
            tokenize(p, eol, tk);
            if (tk.t.size() >= 2 && tk.str(0) == "newmtl") {
                mtls.emplace_back(rest_of_line(p, eol, 6), "");
            } else if (tk.t.size() >= 2 && tk.str(0) == "map_Kd" && !mtls.empty()) {
                // Options (-s u v w, -bm x, ...) come first: the file name is the last token.
                mtls.back().second = mtl_dir + tk.str(tk.t.size() - 1);
            }
            p = eol + 1;
        }
    }
}

// Texture path of each used material; a file without usemtl takes the MTL's first material.
void resolve_materials(const char *obj_path, ObjData &d, std::vector<std::string> &tex) {
    std::vector<std::pair<std::string, std::string>> mtls;
    read_mtl_libraries(obj_path, d, mtls);
    if (d.mat_names.size() == 1 && d.used_default && !mtls.empty()) d.mat_names[0] = mtls[0].first;
    tex.assign(d.mat_names.size(), "");
    for (size_t i = 0; i < d.mat_names.size(); i++)
        for (const auto &mt : mtls)
            if (mt.first == d.mat_names[i]) tex[i] = mt.second;
    for (size_t i = 0; i < tex.size(); i++)
        if (!tex[i].empty() && !file_exists(tex[i])) {
            mx_warn("%s: texture %s of material '%s' not found; ignored", obj_path, tex[i].c_str(),
                    d.mat_names[i].c_str());
            tex[i].clear();
        }
}

template <class T> T *copy_array(const std::vector<T> &v) {
    T *p = (T *)malloc(v.size() ? v.size() * sizeof(T) : sizeof(T));
    if (p && !v.empty()) memcpy(p, v.data(), v.size() * sizeof(T));
    return p;
}

int check_indices(const std::vector<int32_t> &idx, size_t count, bool allow_missing, const char *what,
                  const char *path, mx_status *st) {
    for (size_t i = 0; i < idx.size(); i++) {
        int32_t v = idx[i];
        if (v < 0 && allow_missing) continue;
        if (v < 0 || (size_t)v >= count)
            return mx_fail(st, MX_EINPUT, "%s: face %zu: %s index %d out of range (the file has %zu)", path, i / 3,
                           what, v < 0 ? v : v + 1, count);
    }
    return 0;
}

int obj_to_mesh(const char *path, ObjData &d, mx_mesh *m, mx_status *st) {
    size_t nv = d.pos.size() / 3, nt = d.uv.size() / 2, nn = d.nrm.size() / 3, nf = d.tri.size() / 3;
    if (nf == 0 && nv == 0) /* a text file renamed .obj, say */
        return mx_fail(st, MX_EINPUT, "%s holds no OBJ data (no 'v' or 'f' lines): is it a mesh?", path);
    if (nf == 0) return mx_fail(st, MX_EINPUT, "%s: no faces (%zu vertices, no 'f' lines)", path, nv);
    if (check_indices(d.tri, nv, false, "vertex", path, st)) return -1;
    if (d.any_uv && check_indices(d.tri_uv, nt, true, "texcoord", path, st)) return -1;
    if (d.any_nrm && check_indices(d.tri_nrm, nn, true, "normal", path, st)) return -1;
    std::vector<std::string> tex;
    resolve_materials(path, d, tex);
    m->nverts = (int)nv;
    m->nfaces = (int)nf;
    m->pos = copy_array(d.pos);
    m->faces = copy_array(d.tri);
    if (d.any_uv) {
        m->nuv = (int)nt;
        m->uv = copy_array(d.uv);
        m->face_uv = copy_array(d.tri_uv);
    }
    if (d.any_nrm) {
        m->nnrm = (int)nn;
        m->nrm = copy_array(d.nrm);
        m->face_nrm = copy_array(d.tri_nrm);
    }
    m->nmat = (int)d.mat_names.size();
    m->mats = (mx_material *)calloc((size_t)m->nmat, sizeof(mx_material));
    if (m->nmat > 1) m->face_mat = copy_array(d.tri_mat);
    if (!m->pos || !m->faces || (d.any_uv && (!m->uv || !m->face_uv)) ||
        (d.any_nrm && (!m->nrm || !m->face_nrm)) || !m->mats || (m->nmat > 1 && !m->face_mat))
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    for (int i = 0; i < m->nmat; i++) {
        copy_name(m->mats[i].name, sizeof m->mats[i].name, d.mat_names[(size_t)i]);
        copy_name(m->mats[i].texture_path, sizeof m->mats[i].texture_path, tex[(size_t)i]);
    }
    return 0;
}

int read_obj(const char *path, mx_mesh *m, mx_status *st) {
    std::string text;
    if (read_text_file(path, text, st)) return -1;
    ObjData d;
    if (parse_obj_text(text, path, d, st)) return -1;
    return obj_to_mesh(path, d, m, st);
}

// OpenMesh's PLY reader loops forever on some malformed headers (no end_header, a keyword
// where a name should be), so the header is checked here first: every line must be one
// OpenMesh reads the way the PLY format means it, and end_header must come.
bool ply_header_line_ok(const std::string &line) {
    std::vector<std::string> w;
    for (size_t i = 0; i < line.size();) {
        while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) i++;
        size_t j = i;
        while (j < line.size() && line[j] != ' ' && line[j] != '\t' && line[j] != '\r') j++;
        if (j > i) w.push_back(line.substr(i, j - i));
        i = j;
    }
    static const char *const kws[] = {"format", "element", "property", "end_header", "ply"};
    static const char *const types[] = {"char",   "uchar",  "short", "ushort",  "int",     "uint",
                                        "float",  "double", "int8",  "uint8",   "int16",   "uint16",
                                        "int32",  "uint32", "float32", "float64"};
    auto is_type = [&](const std::string &t) {
        for (const char *k : types)
            if (t == k) return true;
        return false;
    };
    if (w.empty()) return false;
    if (w[0] == "comment" || w[0] == "obj_info") return true;
    for (const char *k : kws)
        for (size_t i = 1; i < w.size(); i++)
            if (w[i] == k) return false; // a keyword in a name's place makes OpenMesh lose its way
    if (w[0] == "format")
        return w.size() == 3 && w[2] == "1.0" &&
               (w[1] == "ascii" || w[1] == "binary_little_endian" || w[1] == "binary_big_endian");
    if (w[0] == "element") return w.size() == 3 && w[2].find_first_not_of("0123456789") == std::string::npos;
    if (w[0] == "property")
        return (w.size() == 3 && is_type(w[1])) || (w.size() == 5 && w[1] == "list" && is_type(w[2]) && is_type(w[3]));
    return false;
}

int check_ply_header(const char *path, mx_status *st) {
    FILE *f = fopen(path, "rb");
    if (!f) return mx_fail(st, MX_EINPUT, "%s: cannot open: %s", path, strerror(errno));
    std::string head(65536, '\0');
    head.resize(fread(&head[0], 1, head.size(), f));
    fclose(f);
    size_t pos = 0;
    bool seen_element = false; // OpenMesh crashes on a property before any element
    for (int line_no = 1;; line_no++) {
        size_t nl = head.find('\n', pos);
        if (nl == std::string::npos)
            return mx_fail(st, MX_EINPUT, "%s: PLY header without end_header in its first 64 KiB", path);
        std::string line = head.substr(pos, nl - pos);
        if (!line.empty() && line.back() == '\r') line.pop_back();
        pos = nl + 1;
        if (line_no == 1) {
            if (line != "ply") return mx_fail(st, MX_EINPUT, "%s: not a PLY file (first line is not 'ply')", path);
        } else if (line == "end_header") {
            return 0;
        } else if (!ply_header_line_ok(line) || (line_no == 2) != (line.compare(0, 7, "format ") == 0) ||
                   (!seen_element && line.compare(0, 9, "property ") == 0)) {
            return mx_fail(st, MX_EINPUT, "%s: PLY header line %d is malformed", path, line_no);
        }
        seen_element |= line.compare(0, 8, "element ") == 0;
    }
}

// A count word: decimal digits only (no sign, no embedded NUL), at most 18 of them.
bool parse_count(const std::string &w, unsigned long long *out) {
    if (w.empty() || w.size() > 18) return false;
    unsigned long long n = 0;
    for (char ch : w) {
        if (ch < '0' || ch > '9') return false;
        n = n * 10 + (unsigned long long)(ch - '0');
    }
    *out = n;
    return true;
}

// A number word as OpenMesh's stream reads one: the whole word, finite.
bool is_number(const std::string &w) {
    char *end;
    double v = strtod(w.c_str(), &end);
    return end == w.c_str() + w.size() && std::isfinite(v);
}

// A whole word that is a number but not a finite one (nan, inf, 1e39). OpenMesh's text readers
// stop at one and report no faces; its binary STL reader merges vertices by position, so NaN
// corners lose their faces silently. Such files are refused here first.
bool is_nonfinite_number(const std::string &w) {
    char *end;
    float v = strtof(w.c_str(), &end); // as the readers store it: 1e39 is inf
    return !w.empty() && end == w.c_str() + w.size() && !std::isfinite(v);
}

int fail_nonfinite(const char *path, long line, const std::string &w, mx_status *st) {
    return mx_fail(st, MX_EINPUT, "%s:%ld: non-finite coordinate '%s'", path, line, w.c_str());
}

// Every number word of text from `from` on is finite; with after_vertex, only the three words
// after each "vertex" (ASCII STL, whose solid name may be any word).
int check_text_coordinates(const char *path, const std::string &text, size_t from, bool after_vertex, mx_status *st) {
    long line = 1 + (long)std::count(text.begin(), text.begin() + (long)from, '\n');
    int want = after_vertex ? 0 : -1; // words still to check after "vertex"; -1: all
    for (size_t i = from; i < text.size();) {
        if (text[i] == '\n') line++;
        if (isspace((unsigned char)text[i])) {
            i++;
            continue;
        }
        size_t j = i;
        while (j < text.size() && !isspace((unsigned char)text[j])) j++;
        std::string w = text.substr(i, j - i);
        if (want != 0 && is_nonfinite_number(w)) return fail_nonfinite(path, line, w, st);
        if (after_vertex) want = w == "vertex" ? 3 : want > 0 ? want - 1 : 0;
        i = j;
    }
    return 0;
}

// An ASCII PLY's body (after end_header) holds only numbers: all finite.
int check_ply_coordinates(const char *path, mx_status *st) {
    std::string text;
    if (read_text_file(path, text, st)) return -1;
    size_t end = text.find("end_header");
    if (text.find("format ascii") > end || end == std::string::npos) return 0; // binary: checked after the read
    return check_text_coordinates(path, text, end + 10, false, st);
}

// STL: a binary file (84 + 50 bytes per triangle) has 9 finite corner floats per triangle; an
// ASCII one finite words after each "vertex".
int check_stl_coordinates(const char *path, mx_status *st) {
    std::string d;
    if (read_text_file(path, d, st)) return -1;
    uint32_t n = 0;
    if (d.size() >= 84) memcpy(&n, d.data() + 80, 4);
    if (d.size() < 84 || 84 + 50 * (uint64_t)n != d.size()) return check_text_coordinates(path, d, 0, true, st);
    for (uint32_t t = 0; t < n; t++) {
        float v[9];
        memcpy(v, d.data() + 84 + 50 * (size_t)t + 12, sizeof v); // after the facet normal
        for (int k = 0; k < 9; k++)
            if (!std::isfinite(v[k]))
                return mx_fail(st, MX_EINPUT, "%s: triangle %u: non-finite coordinate", path, t);
    }
    return 0;
}

// OpenMesh's OFF reader reads words, not lines, and trusts each face's corner count: one word
// too many or too few (or a word that is not a number) shifts every later word, and a corner count
// of 10^20 then costs gigabytes. So ASCII OFF is checked here first, line by line, as OFF writers
// write it: "nv nf ne", then one vertex per line (3 numbers for OFF; the same count, at least 3,
// on every line for the COFF/NOFF/STOFF variants), then one face per line (its corner count, that
// many vertex indices below nv: OpenMesh reads a face colour as the next face). Binary OFF is
// refused.
int check_off_counts(const char *path, mx_status *st) {
    std::string text;
    if (read_text_file(path, text, st)) return -1;
    std::vector<std::vector<std::string>> lines; // non-empty, non-comment lines as words
    for (size_t pos = 0; pos < text.size();) {
        size_t nl = text.find('\n', pos);
        if (nl == std::string::npos) nl = text.size();
        std::vector<std::string> w;
        for (size_t i = pos; i < nl;) {
            while (i < nl && isspace((unsigned char)text[i])) i++;
            size_t j = i;
            while (j < nl && !isspace((unsigned char)text[j])) j++;
            if (j > i && text[i] == '#') break;
            if (j > i) w.push_back(text.substr(i, j - i));
            i = j;
        }
        if (!w.empty()) lines.push_back(w);
        pos = nl + 1;
    }
    if (lines.empty() || lines[0][0].size() < 3 || lines[0][0].compare(lines[0][0].size() - 3, 3, "OFF"))
        return mx_fail(st, MX_EINPUT, "%s: not an OFF file (no OFF header)", path);
    for (const std::string &w : lines[0])
        if (w == "BINARY") return mx_fail(st, MX_EINPUT, "%s: binary OFF is not supported", path);
    // OpenMesh takes the whole first line as the header and reads the counts after it, so counts
    // on the header line would leave them unread (uninitialised: a reserve of gigabytes).
    if (lines[0].size() != 1 || lines.size() < 2)
        return mx_fail(st, MX_EINPUT, "%s: OFF counts must follow the header keyword on a line of their own", path);
    const std::vector<std::string> &counts = lines[1];
    size_t first = 2;
    unsigned long long nv = 0, nf = 0, ne = 0;
    if (counts.size() != 3 || !parse_count(counts[0], &nv) || !parse_count(counts[1], &nf) ||
        !parse_count(counts[2], &ne) || nv > kMaxElements || nf > kMaxElements)
        return mx_fail(st, MX_EINPUT, "%s: OFF vertex and face counts missing or too large", path);
    if (first + nv + nf > lines.size()) // before OpenMesh reserves room for the declared counts
        return mx_fail(st, MX_EINPUT, "%s: OFF header declares %llu vertices and %llu faces, the file has %zu lines",
                       path, nv, nf, lines.size() - first);
    size_t vwords = lines[0][0] == "OFF" || nv == 0 ? 3 : lines[first].size(); // lines[first] exists if nv > 0
    for (size_t v = 0; v < nv; v++) {
        const std::vector<std::string> &w = lines[first + v];
        bool ok = w.size() == vwords && vwords >= 3;
        for (size_t k = 0; ok && k < w.size(); k++) {
            if (is_nonfinite_number(w[k]))
                return mx_fail(st, MX_EINPUT, "%s: OFF vertex %zu: non-finite coordinate '%s'", path, v, w[k].c_str());
            ok = is_number(w[k]);
        }
        if (!ok) return mx_fail(st, MX_EINPUT, "%s: OFF vertex %zu: expected %zu numbers on its line", path, v, vwords);
    }
    for (size_t f = 0; f < nf; f++) {
        const std::vector<std::string> &w = lines[first + (size_t)nv + f];
        unsigned long long n = 0, idx = 0;
        bool ok = parse_count(w[0], &n) && n + 1 == w.size();
        for (size_t k = 1; ok && k < w.size(); k++) ok = parse_count(w[k], &idx) && idx < nv;
        if (!ok)
            return mx_fail(st, MX_EINPUT, "%s: OFF face %zu: corner count '%s' or its indices do not match its line",
                           path, f, w[0].c_str());
    }
    return 0;
}

// PLY / OFF / STL through OpenMesh. Vertex order is the file's (OpenMesh appends vertices it
// must duplicate to represent non-manifold faces at the end).
int read_openmesh(const char *path, mx_mesh *m, mx_status *st) {
    std::string ext = lower_ext(path);
    if (ext == "ply" && (check_ply_header(path, st) || check_ply_coordinates(path, st))) return -1;
    if (ext == "off" && check_off_counts(path, st)) return -1;
    if (ext == "stl" && check_stl_coordinates(path, st)) return -1;
    typedef OpenMesh::PolyMesh_ArrayKernelT<> Mesh;
    Mesh mesh;
    mesh.request_vertex_texcoords2D();
    OpenMesh::IO::Options opt = OpenMesh::IO::Options::VertexTexCoord;
    // Failures are reported through st: silence OpenMesh's own error stream during the read.
    omerr().disable();
    bool ok = OpenMesh::IO::read_mesh(mesh, path, opt);
    omerr().enable();
    if (!ok) return mx_fail(st, MX_EINPUT, "%s: cannot read mesh (missing, malformed or unsupported)", path);
    size_t nv = mesh.n_vertices();
    if (nv > kMaxElements) return mx_fail(st, MX_EINPUT, "%s: too many vertices", path);
    std::vector<float> pos(3 * nv), uv;
    // STL has no texcoords, but OpenMesh's STL reader leaves the requested option set.
    bool has_uv = opt.check(OpenMesh::IO::Options::VertexTexCoord) && lower_ext(path) != "stl";
    if (has_uv) uv.resize(2 * nv);
    for (auto vh : mesh.vertices()) {
        auto p = mesh.point(vh);
        size_t i = (size_t)vh.idx();
        for (int k = 0; k < 3; k++) pos[3 * i + (size_t)k] = p[k];
        if (has_uv) {
            auto t = mesh.texcoord2D(vh);
            uv[2 * i] = t[0];
            uv[2 * i + 1] = t[1];
        }
    }
    for (size_t i = 0; i < pos.size(); i++)
        if (!std::isfinite(pos[i]))
            return mx_fail(st, MX_EINPUT, "%s: vertex %zu has a non-finite coordinate", path, i / 3);
    std::vector<int32_t> tri;
    std::vector<int32_t> poly;
    for (auto fh : mesh.faces()) {
        poly.clear();
        for (auto vh : mesh.fv_range(fh)) poly.push_back(vh.idx());
        for (size_t i = 1; i + 1 < poly.size(); i++) {
            tri.push_back(poly[0]);
            tri.push_back(poly[i]);
            tri.push_back(poly[i + 1]);
        }
    }
    if (tri.empty()) return mx_fail(st, MX_EINPUT, "%s: no faces", path);
    m->nverts = (int)nv;
    m->nfaces = (int)(tri.size() / 3);
    m->pos = copy_array(pos);
    m->faces = copy_array(tri);
    m->nmat = 1;
    m->mats = (mx_material *)calloc(1, sizeof(mx_material));
    if (has_uv) {
        m->nuv = (int)nv;
        m->uv = copy_array(uv);
        m->face_uv = copy_array(tri);
    }
    if (!m->pos || !m->faces || !m->mats || (has_uv && (!m->uv || !m->face_uv)))
        return mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    copy_name(m->mats[0].name, sizeof m->mats[0].name, "default");
    return 0;
}

} // namespace

extern "C" int mx_io_read_mesh(const char *path, mx_mesh *out, mx_status *st) {
    *out = mx_mesh{};
    std::string ext = lower_ext(path);
    int rc;
    try {
        if (ext == "obj") rc = read_obj(path, out, st);
        else if (ext == "ply" || ext == "off" || ext == "stl") rc = read_openmesh(path, out, st);
        else rc = mx_fail(st, MX_EINPUT, "%s: unknown mesh format '.%s' (expected .obj .ply .off .stl)", path, ext.c_str());
    } catch (const std::bad_alloc &) {
        rc = mx_fail(st, MX_ENOMEM, "%s: out of memory", path);
    } catch (const std::exception &e) {
        rc = mx_fail(st, MX_EINPUT, "%s: cannot read mesh: %s", path, e.what());
    }
    if (rc) {
        mx_mesh_free(out);
        return -1;
    }
    copy_name(out->source_path, sizeof out->source_path, path);
    return 0;
}
