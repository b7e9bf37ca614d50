// The grooves mode's deferred pixels (grooves_defer.glsl). Per list (list 2 s + k: slot s's pixels
// of class k; DEFER_SLOTS slots): a DrawArraysIndirectCommand over its 4x4 tiles (the resolve,
// drawn on the frame) and one over the 4x4 blocks of its pixels packed densely (the cast, drawn
// on the pack target), and its pixel count; then the pixels deferred and those that found no
// slot; then the items: each list's tiles (y << 16 | x) from list * deferCapacity, each slot's
// pixels (y << 16 | x) from 2 DEFER_SLOTS deferCapacity + slot * packCapacity, class 0's upward
// from there and class 1's downward from its end (a pixel takes a slot once: the two fit).
layout(std430, binding = 3) coherent buffer DeferLists {
  uint deferCmd[4 * 2 * DEFER_SLOTS];
  uint packCmd[4 * 2 * DEFER_SLOTS];
  uint packCount[2 * DEFER_SLOTS];
  uint deferCount[2];
  uint deferItem[];
};
uniform uint deferCapacity;
uniform uint packCapacity;

uint packedPixelItem(uint list, uint k) {
  return 2u * uint(DEFER_SLOTS) * deferCapacity + (list >> 1) * packCapacity + ((list & 1u) == 0u ? k : packCapacity - 1u - k);
}
