# Component: estimation (targets are added by the component's owner)
