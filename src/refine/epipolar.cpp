#include "view_selection/refine/epipolar.h"

#include <algorithm>
#include <map>
#include <utility>

namespace view_selection::refine {

std::vector<EpipolarPair> epipolarPairs(const std::vector<Match>& matches, size_t per_pair, size_t min_matches,
                                        const std::function<bool(int)>& known,
                                        const std::function<Eigen::Vector2d(int, int)>& pixel,
                                        const std::function<Eigen::Vector4d(int)>& intrinsics) {
  using List = std::vector<std::pair<Observation, Observation>>;
  std::map<std::pair<int, int>, List> by_pair;
  // A pair's matches come one after the other (the bridge writes them pair by pair): the pair's
  // list and whether its images are known are looked up once a run, not once a match (a
  // 30-minute session has 3.7 million matches in 23,000 pairs).
  std::pair<int, int> last_ids{0, 0};
  List* last = nullptr;  // the run's list; nullptr: an image of the run's pair is not known
  bool in_run = false;
  for (const Match& m : matches) {
    if (m.a.image_id == m.b.image_id) continue;
    const bool swap = m.a.image_id > m.b.image_id;
    const std::pair<int, int> ids{std::min(m.a.image_id, m.b.image_id), std::max(m.a.image_id, m.b.image_id)};
    if (!in_run || ids != last_ids) {
      in_run = true;
      last_ids = ids;
      last = known(ids.first) && known(ids.second) ? &by_pair[ids] : nullptr;
    }
    if (!last) continue;
    if (!pixel(m.a.image_id, m.a.point2D_idx).allFinite() || !pixel(m.b.image_id, m.b.point2D_idx).allFinite())
      continue;
    last->emplace_back(swap ? m.b : m.a, swap ? m.a : m.b);
  }
  std::vector<EpipolarPair> out;
  const auto ray = [&](const Observation& o) {
    const Eigen::Vector4d k = intrinsics(o.image_id);
    const Eigen::Vector2d x = pixel(o.image_id, o.point2D_idx);
    return Eigen::Vector3d((x.x() - k[2]) / k[0], (x.y() - k[3]) / k[1], 1.0);
  };
  for (const auto& [ids, list] : by_pair) {
    if (list.size() < std::max<size_t>(min_matches, 1) || per_pair == 0) continue;
    EpipolarPair p;
    p.a = ids.first;
    p.b = ids.second;
    const Eigen::Vector4d ka = intrinsics(p.a), kb = intrinsics(p.b);
    p.focal_a = {ka[0], ka[1]};
    p.focal_b = {kb[0], kb[1]};
    const size_t n = std::min(per_pair, list.size());
    for (size_t q = 0; q < n; ++q) {
      const auto& [a, b] = list[q * list.size() / n];
      p.rays_a.push_back(ray(a));
      p.rays_b.push_back(ray(b));
    }
    out.push_back(std::move(p));
  }
  return out;
}

}  // namespace view_selection::refine
