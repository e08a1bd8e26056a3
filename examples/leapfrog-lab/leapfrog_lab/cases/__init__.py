"""leapfrog-lab's own cases (registered in the entry-point group ``truestep.cases``)."""
