// CGAL region growing of planes on a point set (Shape_detection::Region_growing with
// Least_squares_plane_fit_region, K nearest neighbours, seeds sorted by local plane fit):
// the roof-plane anchor of benchmarks/real_sar.py.
//
// Build:  g++ -O2 -DNDEBUG -std=c++17 cgal_region_growing.cpp -o cgal_region_growing -lgmp -lmpfr
// Usage:  cgal_region_growing in.bin out.bin max_distance max_angle_deg min_region_size k
//   in.bin:  N x 6 float64 little-endian: x y z nx ny nz (local coordinates, unit normals)
//   out.bin: N int32 region labels (0: no region; 1.. in the order CGAL finds them)
// Prints one JSON line: {"seconds": ..., "regions": ..., "n": ...}
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/property_map.h>
#include <CGAL/Shape_detection/Region_growing/Region_growing.h>
#include <CGAL/Shape_detection/Region_growing/Region_growing_on_point_set.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iterator>
#include <utility>
#include <vector>

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = Kernel::Point_3;
using Vector = Kernel::Vector_3;
using Item = std::pair<Point, Vector>;
using Input = std::vector<Item>;
using Point_map = CGAL::First_of_pair_property_map<Item>;
using Normal_map = CGAL::Second_of_pair_property_map<Item>;
namespace RG = CGAL::Shape_detection::Point_set;
using Query = RG::K_neighbor_query<Kernel, Input, Point_map>;
using Region = RG::Least_squares_plane_fit_region<Kernel, Input, Point_map, Normal_map>;
using Sorting = RG::Least_squares_plane_fit_sorting<Kernel, Input, Query, Point_map>;
using Growing = CGAL::Shape_detection::Region_growing<Input, Query, Region,
                                                     typename Sorting::Seed_map>;

int main(int argc, char** argv) {
  if (argc != 7) {
    std::fprintf(stderr, "usage: %s in.bin out.bin max_distance max_angle min_size k\n",
                 argv[0]);
    return 2;
  }
  std::ifstream in(argv[1], std::ios::binary | std::ios::ate);
  const std::size_t bytes = static_cast<std::size_t>(in.tellg());
  in.seekg(0);
  std::vector<double> buf(bytes / sizeof(double));
  in.read(reinterpret_cast<char*>(buf.data()), bytes);
  const std::size_t n = buf.size() / 6;
  Input pts;
  pts.reserve(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double* r = &buf[6 * i];
    pts.emplace_back(Point(r[0], r[1], r[2]), Vector(r[3], r[4], r[5]));
  }
  const auto t0 = std::chrono::steady_clock::now();
  Query query(pts, std::atoi(argv[6]));
  Region region(pts, std::atof(argv[3]), std::atof(argv[4]), std::atoi(argv[5]));
  Sorting sorting(pts, query);
  sorting.sort();
  Growing growing(pts, query, region, sorting.seed_map());
  std::vector<std::vector<std::size_t>> regions;
  growing.detect(std::back_inserter(regions));
  const double sec = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::vector<int> labels(n, 0);
  for (std::size_t r = 0; r < regions.size(); ++r)
    for (std::size_t i : regions[r]) labels[i] = static_cast<int>(r + 1);
  std::ofstream out(argv[2], std::ios::binary);
  out.write(reinterpret_cast<const char*>(labels.data()), n * sizeof(int));
  std::printf("{\"seconds\": %.3f, \"regions\": %zu, \"n\": %zu}\n", sec, regions.size(), n);
  return 0;
}
