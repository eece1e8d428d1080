"""The Q-Tree learning (paper Sect. 4.2): the tree and Eq. 7/13, the C episode kernel, training with
breadth or depth search and the Eq. 14-16 schedule and stop, its parameters and checkpoints."""
