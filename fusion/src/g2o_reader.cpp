#include "fusionloc/fusion/g2o_reader.hpp"

#include <cmath>
#include <cstdlib>
#include <deque>
#include <fstream>
#include <set>
#include <sstream>

#include "fusionloc/common/geometry.hpp"
#include "fusionloc/common/log.hpp"
#include "fusionloc/fusion/cost_functions.hpp"

namespace fl::fusion {
namespace {

// Reads n finite numbers from the line; false with a message if one is missing or bad.
bool ReadNumbers(std::istringstream* in, int n, double* out, std::string* error) {
  for (int k = 0; k < n; ++k) {
    std::string token;
    if (!(*in >> token)) {
      *error = "expected " + std::to_string(n) + " numbers, found " + std::to_string(k);
      return false;
    }
    char* end = nullptr;
    const double v = std::strtod(token.c_str(), &end);
    if (end == token.c_str() || *end != '\0' || !std::isfinite(v)) {
      *error = "field " + std::to_string(k + 1) + " '" + token + "' is not a finite number";
      return false;
    }
    out[k] = v;
  }
  return true;
}

bool ReadId(std::istringstream* in, int* id, std::string* error) {
  std::string token;
  if (!(*in >> token)) {
    *error = "missing vertex id";
    return false;
  }
  char* end = nullptr;
  const long v = std::strtol(token.c_str(), &end, 10);
  if (end == token.c_str() || *end != '\0' || v < 0 || v > 2147483647L) {
    *error = "vertex id '" + token + "' is not a non-negative integer";
    return false;
  }
  *id = static_cast<int>(v);
  return true;
}

bool NoTrailing(std::istringstream* in, std::string* error) {
  std::string extra;
  if (*in >> extra) {
    *error = "unexpected extra field '" + extra + "'";
    return false;
  }
  return true;
}

bool ReadQuaternion(const double* xyzw, Eigen::Quaterniond* q, std::string* error) {
  *q = Eigen::Quaterniond(xyzw[3], xyzw[0], xyzw[1], xyzw[2]);
  if (q->norm() < 1e-9) {
    *error = "quaternion is zero";
    return false;
  }
  q->normalize();
  return true;
}

template <int N>
Eigen::Matrix<double, N, N> UpperToSymmetric(const double* upper) {
  Eigen::Matrix<double, N, N> m;
  int k = 0;
  for (int r = 0; r < N; ++r) {
    for (int c = r; c < N; ++c) {
      m(r, c) = upper[k];
      m(c, r) = upper[k];
      ++k;
    }
  }
  return m;
}

// Poses for a graph of edges only (see the header): the smallest id of each connected part at
// the origin, the others composed along a spanning tree that takes the odometry chain
// (|i - j| = 1) first: a 0-1 breadth-first search where chain edges cost 0 and the others 1.
// Returns the number of connected parts.
template <class Pose, class Edges, class Poses, class Compose, class Invert>
int InitialiseFromEdges(const Edges& edges, const Pose& origin, Poses* poses,
                        const Compose& compose, const Invert& invert) {
  struct Link {
    int to;
    size_t edge;
    bool forward;  // the edge is from -> to (else to -> from: its inverse)
  };
  std::map<int, std::vector<Link>> links;
  for (size_t k = 0; k < edges.size(); ++k) {
    links[edges[k].id_i].push_back({edges[k].id_j, k, true});
    links[edges[k].id_j].push_back({edges[k].id_i, k, false});
  }
  std::set<int> done;
  int parts = 0;
  for (const auto& entry : links) {
    const int root = entry.first;
    if (done.count(root)) continue;
    ++parts;
    (*poses)[root] = origin;
    std::deque<int> queue{root};
    std::map<int, std::pair<int, size_t>> parent;  // vertex -> (parent, edge) when queued
    while (!queue.empty()) {
      const int v = queue.front();
      queue.pop_front();
      if (done.count(v)) continue;
      done.insert(v);
      if (v != root) {
        const auto [from, k] = parent.at(v);
        const bool forward = edges[k].id_i == from;
        (*poses)[v] = compose((*poses)[from], forward ? edges[k].T_i_j : invert(edges[k].T_i_j));
      }
      for (const Link& l : links[v]) {
        if (done.count(l.to)) continue;
        const bool chain = std::abs(static_cast<int64_t>(l.to) - v) == 1;
        // A chain edge may replace a loop-closure parent found earlier.
        auto it = parent.find(l.to);
        if (it == parent.end() || chain) {
          parent[l.to] = {v, l.edge};
          if (chain) {
            queue.push_front(l.to);
          } else {
            queue.push_back(l.to);
          }
        }
      }
    }
  }
  return parts;
}

}  // namespace

Status ReadG2o(std::istream& in, const std::string& name, G2oGraph* graph) {
  *graph = G2oGraph();
  std::string line;
  int line_no = 0;
  std::vector<std::pair<int, int>> edge_lines;  // (line, index) to check ids at the end
  while (std::getline(in, line)) {
    ++line_no;
    std::istringstream ls(line);
    std::string tag;
    if (!(ls >> tag) || tag[0] == '#') continue;
    std::string error;
    const auto fail = [&](const std::string& what) {
      return Status::Error(name + ":" + std::to_string(line_no) + ": " + tag + ": " + what +
                           " (line: '" + line.substr(0, 120) + "')");
    };
    if (tag == "VERTEX_SE2" || tag == "VERTEX_SE3:QUAT") {
      const bool is3 = tag == "VERTEX_SE3:QUAT";
      if ((is3 && !graph->poses2.empty()) || (!is3 && !graph->poses3.empty())) {
        return fail("file mixes 2D and 3D vertices; use one kind per file");
      }
      int id = 0;
      double v[7];
      if (!ReadId(&ls, &id, &error) || !ReadNumbers(&ls, is3 ? 7 : 3, v, &error) ||
          !NoTrailing(&ls, &error)) {
        return fail(error);
      }
      if (graph->poses2.count(id) || graph->poses3.count(id)) {
        return fail("duplicate vertex id " + std::to_string(id));
      }
      if (is3) {
        G2oPose3 pose;
        pose.p = Eigen::Vector3d(v[0], v[1], v[2]);
        if (!ReadQuaternion(v + 3, &pose.q, &error)) return fail(error);
        graph->poses3[id] = pose;
      } else {
        graph->poses2[id] = Eigen::Vector3d(v[0], v[1], NormalizeAngle(v[2]));
      }
    } else if (tag == "EDGE_SE2") {
      int i = 0, j = 0;
      double v[9];
      if (!ReadId(&ls, &i, &error) || !ReadId(&ls, &j, &error) || !ReadNumbers(&ls, 9, v, &error) ||
          !NoTrailing(&ls, &error)) {
        return fail(error);
      }
      if (i == j) return fail("edge from vertex " + std::to_string(i) + " to itself");
      G2oEdge2 e;
      e.id_i = i;
      e.id_j = j;
      e.T_i_j = Eigen::Vector3d(v[0], v[1], NormalizeAngle(v[2]));
      e.information = UpperToSymmetric<3>(v + 3);
      graph->edges2.push_back(e);
      edge_lines.emplace_back(line_no, static_cast<int>(graph->edges2.size() - 1));
    } else if (tag == "EDGE_SE3:QUAT") {
      int i = 0, j = 0;
      double v[28];
      if (!ReadId(&ls, &i, &error) || !ReadId(&ls, &j, &error) ||
          !ReadNumbers(&ls, 28, v, &error) || !NoTrailing(&ls, &error)) {
        return fail(error);
      }
      if (i == j) return fail("edge from vertex " + std::to_string(i) + " to itself");
      G2oEdge3 e;
      e.id_i = i;
      e.id_j = j;
      e.T_i_j.p = Eigen::Vector3d(v[0], v[1], v[2]);
      if (!ReadQuaternion(v + 3, &e.T_i_j.q, &error)) return fail(error);
      e.information = UpperToSymmetric<6>(v + 7);
      graph->edges3.push_back(e);
      edge_lines.emplace_back(line_no, static_cast<int>(graph->edges3.size() - 1));
    } else {
      return fail("unknown tag; supported: VERTEX_SE2, EDGE_SE2, VERTEX_SE3:QUAT, EDGE_SE3:QUAT");
    }
  }
  if (in.bad()) return Status::Error(name + ": read error");
  if (!graph->edges2.empty() && !graph->edges3.empty()) {
    return Status::Error(name + ": file mixes EDGE_SE2 and EDGE_SE3:QUAT; use one kind per file");
  }
  if (graph->num_poses() == 0 && graph->num_edges() == 0) {
    return Status::Error(name + ": no VERTEX_SE2, VERTEX_SE3:QUAT or EDGE line; is this a g2o file?");
  }
  if (graph->num_poses() == 0) {
    // Edges only (several public benchmark collections ship graphs so).
    int parts = 0;
    if (!graph->edges2.empty()) {
      parts = InitialiseFromEdges(
          graph->edges2, Eigen::Vector3d::Zero().eval(), &graph->poses2,
          [](const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
            const Pose2 c = Pose2(a.x(), a.y(), a.z()) * Pose2(b.x(), b.y(), b.z());
            return Eigen::Vector3d(c.x, c.y, c.theta);
          },
          [](const Eigen::Vector3d& a) {
            const Pose2 c = Pose2(a.x(), a.y(), a.z()).inverse();
            return Eigen::Vector3d(c.x, c.y, c.theta);
          });
    } else {
      parts = InitialiseFromEdges(
          graph->edges3, G2oPose3(), &graph->poses3,
          [](const G2oPose3& a, const G2oPose3& b) {
            G2oPose3 c;
            c.p = a.p + a.q * b.p;
            c.q = (a.q * b.q).normalized();
            return c;
          },
          [](const G2oPose3& a) {
            G2oPose3 c;
            c.q = a.q.conjugate();
            c.p = -(c.q * a.p);
            return c;
          });
    }
    graph->initialised_from_edges = true;
    FL_LOG(INFO) << name << ": no VERTEX lines; " << graph->num_poses()
                 << " initial poses from the edges: the odometry chain (edges i -> i+1) first, "
                 << "then a spanning tree of the others, the smallest id at the origin"
                 << (parts > 1 ? " (" + std::to_string(parts) +
                                     " unconnected parts, each from the origin)"
                               : std::string());
  }
  // Every edge must join known vertices of its own kind.
  const bool is3 = graph->is_3d();
  if ((is3 && !graph->edges2.empty()) || (!is3 && !graph->edges3.empty())) {
    return Status::Error(name + ": edges are " + (is3 ? "2D" : "3D") + " but vertices are " +
                         (is3 ? "3D" : "2D"));
  }
  for (const auto& [line_of_edge, index] : edge_lines) {
    const int i = is3 ? graph->edges3[index].id_i : graph->edges2[index].id_i;
    const int j = is3 ? graph->edges3[index].id_j : graph->edges2[index].id_j;
    for (int id : {i, j}) {
      const bool known = is3 ? graph->poses3.count(id) > 0 : graph->poses2.count(id) > 0;
      if (!known) {
        return Status::Error(name + ":" + std::to_string(line_of_edge) +
                             ": edge refers to vertex " + std::to_string(id) +
                             " which no VERTEX line defines");
      }
    }
  }
  return Status::Ok();
}

Status ReadG2oFile(const std::string& path, G2oGraph* graph) {
  std::ifstream in(path);
  if (!in) return Status::Error(path + ": cannot open g2o file (check the path)");
  return ReadG2o(in, path, graph);
}

}  // namespace fl::fusion
