// The grooves mode's deferred pixels (grooves_defer.glsl). Per list (list 2 s + k: slot s's pixels
// of class k; DEFER_SLOTS slots): a DrawArraysIndirectCommand over the 4x4 blocks of its pixels
// packed densely (the cast), and its pixel count; then the pixels deferred and those that found
// no slot; then the items: each slot's pixels (y << 16 | x) from slot * packCapacity, class 0's
// upward and class 1's downward from its end (a pixel takes a slot once: the two fit).
layout(std430, binding = 3) coherent buffer DeferLists {
  uint packCmd[4 * 2 * DEFER_SLOTS];
  uint packCount[2 * DEFER_SLOTS];
  uint deferCount[2];
  uint deferItem[];
};
uniform uint packCapacity;

uint packedPixelItem(uint list, uint k) {
  return (list >> 1) * packCapacity + ((list & 1u) == 0u ? k : packCapacity - 1u - k);
}
