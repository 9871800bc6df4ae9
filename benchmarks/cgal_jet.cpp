// CGAL Monge_via_jet_fitting (degree-2 jet, degree-2 Monge form) at every point, with the
// neighbours given (kNN computed in Python). Peer anchor for benchmarks/bench_curvature.py.
//
// Build:  g++ -O3 -DNDEBUG -fopenmp -std=c++17 -I/usr/include/eigen3 cgal_jet.cpp -o cgal_jet
// Usage:  cgal_jet xyz.bin knn.bin out.bin
//   xyz.bin: N x 3 float64 little-endian (local coordinates)
//   knn.bin: N x k int32 neighbour indices (self included), k inferred from the file size
//   out.bin: N x 2 float64 principal curvatures (k1, k2) as returned by CGAL
// Prints one JSON line: {"fit_seconds": ..., "read_seconds": ..., "n": ..., "k": ..., "threads": ...}
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Monge_via_jet_fitting.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <vector>
#include <omp.h>

typedef CGAL::Simple_cartesian<double> K;
typedef K::Point_3 Point;
typedef CGAL::Monge_via_jet_fitting<K> Fitter;
typedef Fitter::Monge_form Monge;

static std::vector<char> slurp(const char* path) {
  std::ifstream f(path, std::ios::binary | std::ios::ate);
  if (!f) { std::cerr << "cannot open " << path << "\n"; std::exit(2); }
  std::streamsize n = f.tellg();
  f.seekg(0);
  std::vector<char> buf(n);
  f.read(buf.data(), n);
  return buf;
}

int main(int argc, char** argv) {
  if (argc < 4) { std::cerr << "usage: cgal_jet xyz.bin knn.bin out.bin\n"; return 1; }
  auto t0 = std::chrono::steady_clock::now();
  std::vector<char> xb = slurp(argv[1]), kb = slurp(argv[2]);
  const size_t n = xb.size() / (3 * sizeof(double));
  const size_t k = kb.size() / (n * sizeof(int32_t));
  const double* xyz = reinterpret_cast<const double*>(xb.data());
  const int32_t* knn = reinterpret_cast<const int32_t*>(kb.data());
  std::vector<Point> pts(n);
  for (size_t i = 0; i < n; ++i) pts[i] = Point(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
  std::vector<double> out(2 * n, 0.0);
  auto t1 = std::chrono::steady_clock::now();
  long failed = 0;
#pragma omp parallel reduction(+ : failed)
  {
    std::vector<Point> nb(k);
#pragma omp for schedule(dynamic, 4096)
    for (long i = 0; i < (long)n; ++i) {
      for (size_t j = 0; j < k; ++j) nb[j] = pts[knn[i * k + j]];
      // the query point first: CGAL's Monge origin is the projection of the first point
      for (size_t j = 0; j < k; ++j)
        if (knn[i * k + j] == i) { std::swap(nb[0], nb[j]); break; }
      try {
        Fitter fitter;
        Monge m = fitter(nb.begin(), nb.end(), 2, 2);
        out[2 * i] = m.principal_curvatures(0);
        out[2 * i + 1] = m.principal_curvatures(1);
      } catch (...) {
        ++failed;
      }
    }
  }
  auto t2 = std::chrono::steady_clock::now();
  std::ofstream fo(argv[3], std::ios::binary);
  fo.write(reinterpret_cast<const char*>(out.data()), out.size() * sizeof(double));
  std::printf("{\"fit_seconds\": %.6f, \"read_seconds\": %.6f, \"n\": %zu, \"k\": %zu, "
              "\"threads\": %d, \"failed\": %ld}\n",
              std::chrono::duration<double>(t2 - t1).count(),
              std::chrono::duration<double>(t1 - t0).count(), n, k, omp_get_max_threads(), failed);
  return 0;
}
