# Component: mapping (targets are added by the component's owner)
