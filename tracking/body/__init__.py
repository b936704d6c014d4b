"""The articulated body model (thesis 6.2.2), BVH in and out, retargeting and export."""
