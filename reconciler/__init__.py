"""The reconciler: the git branch's head commit becomes the retained launch topics."""
