// Reader of g2o pose-graph files (the format of the standard SLAM benchmark graphs).
//
//   VERTEX_SE2 id x y theta
//   EDGE_SE2 i j x y theta  I11 I12 I13 I22 I23 I33             (upper-triangular information)
//   VERTEX_SE3:QUAT id x y z qx qy qz qw
//   EDGE_SE3:QUAT i j x y z qx qy qz qw  I11 I12 .. I16 I22 .. I66 (21 upper-triangular entries,
//                                                         order x y z rx ry rz)
//
// The edge measurement is T_i_j, the pose of vertex j in the frame of vertex i. Angles are
// wrapped to [-pi, pi) and quaternions normalised on reading (as Ceres' examples do).
// A file of edges only, without any VERTEX line (several public benchmark collections ship
// graphs so), is accepted: the initial poses are composed from the edges, along the odometry
// chain (edges between consecutive ids) first and then a spanning tree of the other edges,
// with the smallest id (of each unconnected part) at the origin; a log line says so
// (G2oGraph::initialised_from_edges). Information matrices are kept as written: any
// symmetric positive-definite one is accepted, whatever the spread of its entries.
// Blank lines and lines starting with '#' are skipped. Anything else (an unknown tag, a
// missing or non-numeric field, a non-finite number, a zero quaternion, an edge to an unknown
// vertex, an edge from a vertex to itself, a duplicate vertex id, a file mixing 2D and 3D) is an
// error naming file:line.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <istream>
#include <map>
#include <string>
#include <vector>

#include "fusionloc/common/status.hpp"

namespace fl::fusion {

struct G2oEdge2 {
  int id_i = 0;
  int id_j = 0;
  Eigen::Vector3d T_i_j = Eigen::Vector3d::Zero();  // x, y, theta of j in i
  Eigen::Matrix3d information = Eigen::Matrix3d::Identity();
};

struct G2oPose3 {
  Eigen::Vector3d p = Eigen::Vector3d::Zero();
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW
};

struct G2oEdge3 {
  int id_i = 0;
  int id_j = 0;
  G2oPose3 T_i_j;
  Eigen::Matrix<double, 6, 6> information = Eigen::Matrix<double, 6, 6>::Identity();
  EIGEN_MAKE_ALIGNED_OPERATOR_NEW
};

struct G2oGraph {
  std::map<int, Eigen::Vector3d> poses2;  // id -> T_world_i (x, y, theta)
  std::vector<G2oEdge2> edges2;
  std::map<int, G2oPose3, std::less<int>, Eigen::aligned_allocator<std::pair<const int, G2oPose3>>>
      poses3;  // id -> T_world_i
  std::vector<G2oEdge3, Eigen::aligned_allocator<G2oEdge3>> edges3;

  bool initialised_from_edges = false;  // the file had no VERTEX line (see above)

  bool is_3d() const { return !poses3.empty(); }
  size_t num_poses() const { return poses2.size() + poses3.size(); }
  size_t num_edges() const { return edges2.size() + edges3.size(); }
};

// Parses `in`; `name` is used in error messages. On error, *graph is left unspecified.
Status ReadG2o(std::istream& in, const std::string& name, G2oGraph* graph);
Status ReadG2oFile(const std::string& path, G2oGraph* graph);

}  // namespace fl::fusion
