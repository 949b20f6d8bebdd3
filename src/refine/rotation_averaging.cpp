#include "view_selection/refine/rotation_averaging.h"

#include "view_selection/core/exceptions.h"
#include "view_selection/io/file_ops.h"

#include <Eigen/SVD>
#include <Eigen/Sparse>
#include <Eigen/SparseCholesky>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

namespace view_selection::refine {

namespace {

constexpr char kMagic[8] = {'V', 'S', 'R', 'O', 'T', 'A', 'T', '1'};
constexpr size_t kRecord = 4 + 4 + 4 * 8;

/// The rotation nearest to `m` (Frobenius norm).
Eigen::Matrix3d nearestRotation(const Eigen::Matrix3d& m) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d d = Eigen::Matrix3d::Identity();
  d(2, 2) = (svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0 ? -1.0 : 1.0;
  return svd.matrixU() * d * svd.matrixV().transpose();
}

double angleOf(const Eigen::Matrix3d& r) {
  return std::acos(std::clamp((r.trace() - 1.0) / 2.0, -1.0, 1.0));
}

}  // namespace

RotationAveragingResult averageRotations(const std::map<int, Eigen::Quaterniond>& start,
                                         const std::vector<RelativeRotation>& relatives, int held,
                                         int iterations) {
  RotationAveragingResult out;
  out.rotations = start;
  if (!start.count(held)) return out;
  // The unknowns: every image but the held one, three rows each (one column of its rotation).
  std::map<int, int> index;
  for (const auto& [id, q] : start)
    if (id != held) index.emplace(id, static_cast<int>(index.size()));
  std::vector<const RelativeRotation*> edges;
  for (const RelativeRotation& e : relatives)
    if (e.a != e.b && start.count(e.a) && start.count(e.b) && e.sigma > 0.0 &&
        e.rotation_ba.coeffs().allFinite())
      edges.push_back(&e);
  if (index.empty() || edges.empty()) return out;
  std::map<int, Eigen::Matrix3d> current;
  for (const auto& [id, q] : start) current[id] = q.normalized().toRotationMatrix();
  std::vector<Eigen::Matrix3d> measured;
  std::vector<double> weight;
  double strongest = 0.0;
  for (const RelativeRotation* e : edges) {
    measured.push_back(e->rotation_ba.normalized().toRotationMatrix());
    weight.push_back(1.0 / (e->sigma * e->sigma));
    strongest = std::max(strongest, weight.back());
  }
  // A pull to the start far weaker than any relative rotation: it only decides what the relative
  // rotations leave free (a group of images not connected to the held one).
  const double pull = 1e-9 * strongest;
  const int n = static_cast<int>(index.size());
  const Eigen::Matrix3d& fixed = current.at(held);
  Eigen::MatrixXd pulled =
      Eigen::MatrixXd::Zero(3 * n, 3);  // the pull's side, the same every solve
  for (const auto& [id, k] : index) pulled.middleRows(3 * k, 3) = pull * current.at(id);
  Eigen::SimplicialLDLT<Eigen::SparseMatrix<double>> solver;
  for (int it = 0; it < iterations; ++it) {
    std::vector<Eigen::Triplet<double>> triplets;
    triplets.reserve(static_cast<size_t>(n) * 9 + edges.size() * 36);
    Eigen::MatrixXd rhs = pulled;
    const auto block = [&](int row, int col, const Eigen::Matrix3d& m) {
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j) triplets.emplace_back(3 * row + i, 3 * col + j, m(i, j));
    };
    for (const auto& [id, k] : index) block(k, k, pull * Eigen::Matrix3d::Identity());
    // Each relative rotation: x_b - M x_a = 0 for every column x of the rotations, weighted.
    for (size_t q = 0; q < edges.size(); ++q) {
      const Eigen::Matrix3d& m = measured[q];
      const double w = weight[q];
      const auto ia = index.find(edges[q]->a), ib = index.find(edges[q]->b);
      const bool a_free = ia != index.end(), b_free = ib != index.end();
      if (b_free) block(ib->second, ib->second, w * Eigen::Matrix3d::Identity());
      if (a_free) block(ia->second, ia->second, w * Eigen::Matrix3d::Identity());  // M^T M = I
      if (a_free && b_free) {
        block(ib->second, ia->second, -w * m);
        block(ia->second, ib->second, -w * m.transpose());
      } else if (b_free) {
        rhs.middleRows(3 * ib->second, 3) += w * m * fixed;
      } else if (a_free) {
        rhs.middleRows(3 * ia->second, 3) += w * m.transpose() * fixed;
      }
    }
    Eigen::SparseMatrix<double> a(3 * n, 3 * n);
    a.setFromTriplets(triplets.begin(), triplets.end());
    if (it == 0) solver.analyzePattern(a);  // the same pattern every solve: only the weights change
    solver.factorize(a);
    if (solver.info() != Eigen::Success) return out;
    const Eigen::MatrixXd x = solver.solve(rhs);
    if (solver.info() != Eigen::Success || !x.allFinite()) return out;
    double largest_change = 0.0;
    for (const auto& [id, k] : index) {
      const Eigen::Matrix3d r = nearestRotation(x.middleRows(3 * k, 3));
      largest_change = std::max(largest_change, angleOf(r * current.at(id).transpose()));
      current[id] = r;
    }
    out.iterations = it + 1;
    out.solved = true;
    // Cauchy reweighting at each relative rotation's sigma.
    for (size_t q = 0; q < edges.size(); ++q) {
      const double residual = angleOf(
          current.at(edges[q]->b) * current.at(edges[q]->a).transpose() * measured[q].transpose());
      const double ratio = residual / edges[q]->sigma;
      weight[q] = 1.0 / (edges[q]->sigma * edges[q]->sigma) / (1.0 + ratio * ratio);
    }
    if (largest_change < 1e-3 * M_PI / 180.0) break;
  }
  for (const auto& [id, r] : current) out.rotations[id] = Eigen::Quaterniond(r).normalized();
  return out;
}

std::vector<PairRotation> readPairRotations(const std::string& path) {
  const std::vector<uint8_t> bytes = io::readFileBytes(path);
  if (bytes.size() < 16 || std::memcmp(bytes.data(), kMagic, 8) != 0)
    throw core::IoError(path + ": not a pair rotations file (VSROTAT1)");
  uint64_t count = 0;
  std::memcpy(&count, bytes.data() + 8, 8);
  if (count > (bytes.size() - 16) / kRecord || bytes.size() != 16 + kRecord * count)
    throw core::IoError(path + ": " + std::to_string(count) + " pair rotations do not fit its " +
                        std::to_string(bytes.size()) + " bytes");
  std::vector<PairRotation> out(count);
  for (uint64_t q = 0; q < count; ++q) {
    const uint8_t* at = bytes.data() + 16 + kRecord * q;
    int32_t ids[2];
    double wxyz[4];
    std::memcpy(ids, at, 8);
    std::memcpy(wxyz, at + 8, 32);
    const Eigen::Quaterniond r(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    if (!r.coeffs().allFinite() || std::abs(r.norm() - 1.0) > 1e-6)
      throw core::IoError(path + ": pair rotation " + std::to_string(q) + " (images " +
                          std::to_string(ids[0]) + ", " + std::to_string(ids[1]) +
                          ") is not a unit quaternion");
    out[q] = {ids[0], ids[1], r};
  }
  return out;
}

void writePairRotations(const std::string& path, const std::vector<PairRotation>& rotations) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  if (!out) throw core::IoError(path + ": cannot write the pair rotations file");
  out.write(kMagic, 8);
  const uint64_t count = rotations.size();
  out.write(reinterpret_cast<const char*>(&count), 8);
  for (const PairRotation& p : rotations) {
    const int32_t ids[2] = {p.a, p.b};
    const double wxyz[4] = {p.rotation_ba.w(), p.rotation_ba.x(), p.rotation_ba.y(),
                            p.rotation_ba.z()};
    out.write(reinterpret_cast<const char*>(ids), 8);
    out.write(reinterpret_cast<const char*>(wxyz), 32);
  }
  if (!out) throw core::IoError(path + ": writing the pair rotations file failed");
}

}  // namespace view_selection::refine
