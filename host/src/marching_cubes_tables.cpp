// The Marching Cubes case table, derived from first principles instead of typed in.
//
// A case is the inside-corner mask plus one asymptotic-decider bit per face (see
// om_mc_face_bits). For each case:
//  1. Face segments: on every cube face, the sign-changing edges are paired by segments of the
//     iso-contour. Two crossings pair directly; four (an ambiguous face) pair so that the
//     segments cut off the two outside corners when the decider says the inside corners connect,
//     the two inside corners otherwise. Both cells sharing a face see the same segments, which is
//     what makes the surface closed.
//  2. Orientation: each segment is directed so that, seen from outside the cell, the outside
//     corners are on its left. The neighbour sees the face from the other side, so it directs the
//     shared segment the other way: the mesh is consistently oriented, normals pointing out.
//  3. Loops: every crossing lies on two faces and ends one segment on each, so the directed
//     segments form disjoint closed loops; each loop bounds one polygon of the surface.
//  4. Triangulation: each polygon is triangulated with diagonals that never join two crossings
//     on a common face: only such a diagonal could also be drawn by the neighbour across that
//     face, which would put one edge in four triangles. A loop that cannot be triangulated that
//     way becomes a fan around an extra centre vertex (as in Marching Cubes 33), so every mesh
//     edge still belongs to exactly two triangles.
#include <algorithm>
#include <array>
#include <string>
#include <vector>

#include "meshing.hpp"
#include "meshing_math.h"

namespace oclvox::detail {

namespace {

using Vec = std::array<double, 3>;

Vec corner_position(int c) {
    return {double(om_corner_bit(c, 0)), double(om_corner_bit(c, 1)), double(om_corner_bit(c, 2))};
}

// Only the order of crossings along an edge matters for topology, so midpoints stand in for them.
Vec edge_midpoint(int e) {
    Vec p = corner_position(om_edge_corner(e, 0));
    p[e >> 2] = 0.5;
    return p;
}

int edge_between(int c0, int c1) {
    for (int e = 0; e < 12; ++e)
        if ((om_edge_corner(e, 0) == c0 && om_edge_corner(e, 1) == c1) ||
            (om_edge_corner(e, 0) == c1 && om_edge_corner(e, 1) == c0))
            return e;
    throw Error("marching cubes table: corners " + std::to_string(c0) + " and " +
                std::to_string(c1) + " share no edge");
}

bool edge_on_face(int e, int f) {
    const int d = f >> 1, side = f & 1;
    return om_corner_bit(om_edge_corner(e, 0), d) == side &&
           om_corner_bit(om_edge_corner(e, 1), d) == side;
}

bool edges_share_face(int e0, int e1) {
    for (int f = 0; f < 6; ++f)
        if (edge_on_face(e0, f) && edge_on_face(e1, f)) return true;
    return false;
}

// Is r left of the directed line p -> q, seen from outside the cube through face f?
bool left_of(const Vec& p, const Vec& q, const Vec& r, int f) {
    const Vec a{q[0] - p[0], q[1] - p[1], q[2] - p[2]};
    const Vec b{r[0] - p[0], r[1] - p[1], r[2] - p[2]};
    const Vec cross{a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                    a[0] * b[1] - a[1] * b[0]};
    const double outward = (f & 1) ? 1.0 : -1.0;
    return cross[f >> 1] * outward > 0;
}

// Phases 1 and 2: next[e] = the crossing that the directed segment leaving crossing e goes to.
std::array<int, 12> directed_segments(int mask, int face_bits) {
    std::array<int, 12> next;
    next.fill(-1);
    for (int f = 0; f < 6; ++f) {
        int corner[4], edge[4];
        bool inside[4], crossing[4];
        for (int i = 0; i < 4; ++i) corner[i] = om_face_corner(f, i);
        for (int i = 0; i < 4; ++i) {
            inside[i] = (mask >> corner[i]) & 1;
            edge[i] = edge_between(corner[i], corner[(i + 1) % 4]);  // joins corners i and i+1
        }
        int crossings = 0;
        for (int i = 0; i < 4; ++i) crossings += crossing[i] = inside[i] != inside[(i + 1) % 4];

        // Segments as pairs of face-edge slots, with the face corner they cut off (-1: none).
        struct Segment {
            int slot0, slot1, cut_corner;
        };
        Segment segments[2];
        int count = 0;
        if (crossings == 2) {
            int slots[2], n = 0;
            for (int i = 0; i < 4; ++i)
                if (crossing[i]) slots[n++] = i;
            // Adjacent slots i, i+1 surround corner i+1; opposite slots cut off no corner.
            int cut = -1;
            if ((slots[0] + 1) % 4 == slots[1]) cut = slots[1];
            if ((slots[1] + 1) % 4 == slots[0]) cut = slots[0];
            segments[count++] = {slots[0], slots[1], cut};
        } else if (crossings == 4) {
            const bool connect_inside = (face_bits >> f) & 1;
            for (int i = 0; i < 4; ++i)
                if (inside[i] != connect_inside) segments[count++] = {(i + 3) % 4, i, i};
        }

        for (int s = 0; s < count; ++s) {
            int from = edge[segments[s].slot0], to = edge[segments[s].slot1];
            // A corner on a known side: the cut-off one, else any (both sides are uniform).
            const int reference = corner[segments[s].cut_corner >= 0 ? segments[s].cut_corner : 0];
            const bool outside = !((mask >> reference) & 1);
            if (left_of(edge_midpoint(from), edge_midpoint(to), corner_position(reference), f) !=
                outside)
                std::swap(from, to);
            if (next[from] != -1)
                throw Error("marching cubes table: crossing " + std::to_string(from) +
                            " starts two segments in case " + std::to_string(mask));
            next[from] = to;
        }
    }
    return next;
}

// Phase 4: triangulates the polygon `loop` (in order) without diagonals between crossings on a
// common face; returns false if no such triangulation exists.
bool triangulate(const std::vector<int>& loop, std::vector<std::array<int, 3>>& out) {
    const size_t n = loop.size();
    if (n == 3) {
        out.push_back({loop[0], loop[1], loop[2]});
        return true;
    }
    // Triangle (0, 1, k) splits the polygon into (1..k) and (0, k..n-1).
    for (size_t k = 2; k < n; ++k) {
        if (k > 2 && edges_share_face(loop[1], loop[k])) continue;
        if (k < n - 1 && edges_share_face(loop[0], loop[k])) continue;
        const size_t mark = out.size();
        out.push_back({loop[0], loop[1], loop[k]});
        const std::vector<int> first(loop.begin() + 1, loop.begin() + long(k) + 1);
        std::vector<int> second{loop[0]};
        second.insert(second.end(), loop.begin() + long(k), loop.end());
        if ((first.size() < 3 || triangulate(first, out)) &&
            (second.size() < 3 || triangulate(second, out)))
            return true;
        out.resize(mark);
    }
    return false;
}

// The faces of case `mask` with four crossings: the only ones whose decider bit matters.
int ambiguous_faces(int mask) {
    int faces = 0;
    for (int f = 0; f < 6; ++f) {
        int inside[4];
        for (int i = 0; i < 4; ++i) inside[i] = (mask >> om_face_corner(f, i)) & 1;
        if (inside[0] == inside[2] && inside[1] == inside[3] && inside[0] != inside[1])
            faces |= 1 << f;
    }
    return faces;
}

std::vector<uint8_t> build_table() {
    std::vector<uint8_t> table(size_t(OM_MC_ENTRIES) * OM_MC_ENTRY_BYTES, 0);
    for (int index = 0; index < OM_MC_ENTRIES; ++index) {
        const int mask = index & 255, face_bits = index >> 8;
        // Decider bits of faces that are not ambiguous change nothing: such a case is the one
        // without them, built already (its index is lower). Most masks have no ambiguous face.
        const int relevant = face_bits & ambiguous_faces(mask);
        if (relevant != face_bits) {
            const size_t same = size_t(mask | relevant << 8) * OM_MC_ENTRY_BYTES;
            std::copy_n(table.begin() + long(same), OM_MC_ENTRY_BYTES,
                        table.begin() + long(size_t(index) * OM_MC_ENTRY_BYTES));
            continue;
        }
        const std::array<int, 12> next = directed_segments(mask, face_bits);

        // Phase 3: follow the loops, each from its lowest crossing, lowest first.
        std::vector<std::array<int, 3>> triangles;
        std::vector<int> centre_masks;
        std::array<bool, 12> visited{};
        for (int start = 0; start < 12; ++start) {
            if (next[start] == -1 || visited[start]) continue;
            std::vector<int> loop;
            for (int e = start; !visited[e]; e = next[e]) {
                if (next[e] == -1)
                    throw Error("marching cubes table: open loop in case " + std::to_string(index));
                visited[e] = true;
                loop.push_back(e);
            }
            if (loop.size() < 3)
                throw Error("marching cubes table: degenerate loop in case " +
                            std::to_string(index));
            if (triangulate(loop, triangles)) continue;
            // Some loops cannot avoid such a diagonal (a band joining two ambiguous faces:
            // every triangle would need two crossings of one face). They become a fan around a
            // centre vertex of their own, which adds no edge between crossings at all.
            const int centre = OM_MC_CENTRE_BASE + int(centre_masks.size());
            int members = 0;
            for (size_t i = 0; i < loop.size(); ++i) {
                triangles.push_back({centre, loop[i], loop[(i + 1) % loop.size()]});
                members |= 1 << loop[i];
            }
            centre_masks.push_back(members);
        }

        if (triangles.size() > OM_MC_MAX_TRIANGLES || centre_masks.size() > OM_MC_MAX_CENTRES)
            throw Error("marching cubes table: case " + std::to_string(index) + " needs " +
                        std::to_string(triangles.size()) + " triangles and " +
                        std::to_string(centre_masks.size()) + " centres");
        uint8_t* entry = table.data() + size_t(index) * OM_MC_ENTRY_BYTES;
        entry[0] = uint8_t(triangles.size());
        entry[1] = uint8_t(centre_masks.size());
        for (size_t c = 0; c < centre_masks.size(); ++c) {
            entry[2 + 2 * c] = uint8_t(centre_masks[c] & 255);
            entry[3 + 2 * c] = uint8_t(centre_masks[c] >> 8);
        }
        for (size_t t = 0; t < triangles.size(); ++t)
            for (int v = 0; v < 3; ++v)
                entry[OM_MC_TRIANGLES_AT + 3 * t + v] = uint8_t(triangles[t][v]);
    }
    return table;
}

}  // namespace

const std::vector<uint8_t>& marching_cubes_table() {
    static const std::vector<uint8_t> table = build_table();
    return table;
}

}  // namespace oclvox::detail
