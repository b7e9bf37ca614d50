// The grooves mode's deferred pixels (grooves_defer.glsl): a DrawArraysIndirectCommand per list
// (list 2 s + k: slot s's tiles holding a pixel of class k; DEFER_SLOTS slots), the pixels deferred
// and those that found no slot, then each list's 4x4 tiles (y << 16 | x) from list * deferCapacity.
layout(std430, binding = 3) coherent buffer DeferLists {
  uint deferCmd[4 * 2 * DEFER_SLOTS];
  uint deferCount[2];
  uint deferTile[];
};
uniform uint deferCapacity;
