"""Research: the image detector's accuracy and its score threshold."""
