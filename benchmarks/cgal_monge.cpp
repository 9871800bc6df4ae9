// CGAL Monge_via_jet_fitting of any degree at every point, neighbours given: the peer of
// lidarstat's jets (benchmarks/bench_jets.py, d = d' = 4), of its quadric curvature
// (benchmarks/bench_curvature.py, d = d' = 2) and the reference of
// tests/features/test_jets.py::test_equals_cgal.
//
// Build:  g++ -O3 -DNDEBUG -fopenmp -std=c++17 -I/usr/include/eigen3 cgal_monge.cpp -o cgal_monge
// Usage:  cgal_monge xyz.bin knn.bin out.bin d dprime
//   xyz.bin: N x 3 float64 little-endian (local coordinates)
//   knn.bin: N x k int32 neighbour indices (self included), k inferred from the file size
//   out.bin: N x 21 float64: k1 k2 b0 b1 b2 b3 c0 c1 c2 c3 c4 (zeros above dprime),
//            d1 (3), d2 (3), n (3), condition number; NaN rows where CGAL threw
// Prints one JSON line: {"fit_seconds": ..., "read_seconds": ..., "n": ..., "k": ..., ...}
#include <CGAL/Simple_cartesian.h>
#include <CGAL/Monge_via_jet_fitting.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
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
  if (argc < 6) { std::cerr << "usage: cgal_monge xyz.bin knn.bin out.bin d dprime\n"; return 1; }
  const int d = std::atoi(argv[4]), dp = std::atoi(argv[5]);
  auto t0 = std::chrono::steady_clock::now();
  std::vector<char> xb = slurp(argv[1]), kb = slurp(argv[2]);
  const size_t n = xb.size() / (3 * sizeof(double));
  const size_t k = kb.size() / (n * sizeof(int32_t));
  const double* xyz = reinterpret_cast<const double*>(xb.data());
  const int32_t* knn = reinterpret_cast<const int32_t*>(kb.data());
  std::vector<Point> pts(n);
  for (size_t i = 0; i < n; ++i) pts[i] = Point(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
  const int W = 21;
  std::vector<double> out(W * n, 0.0);
  auto t1 = std::chrono::steady_clock::now();
  long failed = 0;
#pragma omp parallel reduction(+ : failed)
  {
    std::vector<Point> nb(k);
#pragma omp for schedule(dynamic, 4096)
    for (long i = 0; i < (long)n; ++i) {
      for (size_t j = 0; j < k; ++j) nb[j] = pts[knn[i * k + j]];
      // the query point first: CGAL's fitting origin is the first point
      for (size_t j = 0; j < k; ++j)
        if (knn[i * k + j] == i) { std::swap(nb[0], nb[j]); break; }
      double* o = &out[W * i];
      try {
        Fitter fitter;
        Monge m = fitter(nb.begin(), nb.end(), d, dp);
        const std::vector<double> c = m.coefficients();
        for (size_t t = 0; t < c.size() && t < 11; ++t) o[t] = c[t];
        K::Vector_3 v[3] = {m.maximal_principal_direction(), m.minimal_principal_direction(),
                            m.normal_direction()};
        for (int a = 0; a < 3; ++a)
          for (int b = 0; b < 3; ++b) o[11 + 3 * a + b] = v[a][b];
        o[20] = fitter.condition_number();
      } catch (...) {
        for (int t = 0; t < W; ++t) o[t] = NAN;
        ++failed;
      }
    }
  }
  auto t2 = std::chrono::steady_clock::now();
  std::ofstream fo(argv[3], std::ios::binary);
  fo.write(reinterpret_cast<const char*>(out.data()), out.size() * sizeof(double));
  std::printf("{\"fit_seconds\": %.6f, \"read_seconds\": %.6f, \"n\": %zu, \"k\": %zu, "
              "\"d\": %d, \"dprime\": %d, \"threads\": %d, \"failed\": %ld}\n",
              std::chrono::duration<double>(t2 - t1).count(),
              std::chrono::duration<double>(t1 - t0).count(), n, k, d, dp,
              omp_get_max_threads(), failed);
  return 0;
}
