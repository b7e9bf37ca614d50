// The processes of one `scanatlas pack` started together by mpirun or srun (OpenMPI): the
// pipeline's per-chunk phases split their chunks over these ranks (pipeline.cpp). A process
// started any other way is a single rank and never touches MPI. mpi.h stays inside
// cluster.cpp.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "common/error.h"

namespace sa {

class Cluster {
 public:
  // Initialises MPI when the environment says mpirun or srun started this process, and limits
  // this rank's threads to its share of the node's cores (cores / ranks on the node). An srun
  // task without an MPI plugin is an error (each would pack the whole input alone).
  static Status start();
  // MPI_Finalize when start() initialised MPI; nothing otherwise.
  static void stop();
  static int rank();
  static int size();
  static bool distributed() { return size() > 1; }
  // Threads this rank runs (its share of the node's cores).
  static int threads();

  // Collectives: every rank calls them in the same order.
  // Root's bytes to every rank.
  static void broadcast(std::vector<uint8_t>& bytes, int root = 0);
  // Every rank's bytes to every rank, indexed by rank.
  static std::vector<std::vector<uint8_t>> allGather(const std::vector<uint8_t>& mine);
  // The same Status on every rank: the failure of the lowest failing rank, else ok. Phases
  // call it where a rank may have failed, so that no rank waits for one that gave up.
  static Status agree(const Status& mine);
};

}  // namespace sa
